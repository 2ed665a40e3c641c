"""The sync logic in virtual time (issue 41, item 6): a cell of cameras, rings, the request engine
and the streams in one process on a virtual clock, with scripted lateness, drops and stalls; its
assertions are exact and do not depend on the machine's load (tests/unit/test_virtual_sync.py)."""

from .camera import MS, Script, VirtualCamera
from .cell import SECOND, Answer, Cell
from .clock import VirtualClock

__all__ = ["MS", "SECOND", "Answer", "Cell", "Script", "VirtualCamera", "VirtualClock"]
