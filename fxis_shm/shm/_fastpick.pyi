# The compiled read of one service's rings (_fastpick.c); fastpick.py says what it answers.
from collections.abc import Callable, Sequence
from typing import Any

from numpy.typing import NDArray

PLAN: int
WAIT: int
REJECT: int
UNSUPPORTED: int
UNREAD: int
RETIRED: int
DOWN: int
TORN: int

class Rings:
    def __init__(
        self, rings: Sequence[tuple[object, ...]], layout: tuple[int, ...], fresh: Callable[[int], NDArray[Any]], /
    ) -> None: ...
    def pick(
        self,
        rings: tuple[int, ...],
        ranks: tuple[int, ...],
        op: int,
        at: int,
        joint: int,
        auto: int,
        tolerance_ns: int,
        horizon_ns: int,
        copy: bool,
        now: int,
        /,
    ) -> tuple[object, ...] | int: ...

def decide_near(*args: object) -> tuple[object, ...]: ...
