"""The compiled same-host read (``fxis_shm.shm._fastpick``, C): for the common requests (an image
or a tuple at a given t*, the latest frames) one call looks at the rings, decides with the C twin
of the engine's decision (fxis_shm/core/pickcore.c) and, if asked, copies the frames out under
the seqlock. Whatever it does not settle (a wait, an error to word, a camera down, a ring
replaced, a torn copy) it leaves to the Python engine, which answers as before.

``Picker`` serves both of its users: the same-host client (fxis_shm.client.fastreads) and the
coordinator (fxis_shm.service.fastanswers). ``AVAILABLE`` is False when the C module is not
built, or FXIS_PURE_PYTHON=1 (fxis_shm._compiled): then every request takes the engine.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from functools import partial
from typing import Any, TypeAlias

import numpy as np
from numpy.typing import NDArray

from fxis_shm.core import timebase
from fxis_shm.shm.cameras import ALIVE_CHECK_NS, STALE_HEARTBEAT_NS
from fxis_shm.shm.ring import RingReader
from fxis_shm.shm.ringheader import FIELDS, STATE_RETIRED

try:
    if os.environ.get("FXIS_PURE_PYTHON") == "1":
        raise ImportError("FXIS_PURE_PYTHON=1")
    from fxis_shm.shm import _fastpick
except ImportError:
    _fastpick = None  # type: ignore[assignment]  # (the stub types the built reader; it may be missing)

AVAILABLE = _fastpick is not None
# Rings.pick's answers that are not frames: why the engine must answer (_fastpick.c)
PLAN, WAIT, REJECT, UNSUPPORTED, UNREAD, RETIRED, DOWN, TORN = range(8)
IMAGE, TUPLE, LATEST = range(3)  # Rings.pick's ops
_WATCHED = ("state", "writer_pid", "write_count", "heartbeat_ns", "period_ns", "delay_ns")
_SYNCS = {None: None, "joint": 1, "independent": 0}  # the sync and wait modes it decides
_WAITS = {None: None, "auto": 1, "none": 0}
_FORMS = 256  # camera lists remembered
# (ring indices, ranks by name, names) of a request's cameras
_Form: TypeAlias = tuple[tuple[int, ...], tuple[int, ...], list[str]]
_INT64_MIN, _INT64_MAX = -(1 << 63), (1 << 63) - 1  # the times the C reader takes


def fresh_array(layouts: Sequence[tuple[tuple[int, ...], str]], k: int) -> NDArray[Any]:
    """An array for a frame of ring ``k``, its pages mapped in now (not during a copy someone waits for)."""
    array = np.empty(*layouts[k])
    array.fill(0)
    return array


class Picker:
    """The C reader of one service's rings (``readers``, the cameras ``names``), deciding with
    the engine's ``settings`` in the service's clock ``clock``; the copies' arrays are pooled,
    up to ``pooled_bytes`` over all cameras (at least 4 per camera)."""

    def __init__(
        self,
        names: Sequence[str],
        readers: Sequence[RingReader],
        settings: Mapping[str, Any],
        clock: str,
        pooled_bytes: int,
    ):
        assert _fastpick is not None
        layout = (
            *(FIELDS[name][1] for name in _WATCHED),
            STATE_RETIRED,
            STALE_HEARTBEAT_NS,
            ALIVE_CHECK_NS,
            timebase.CLOCK_IDS[clock],
        )
        each = pooled_bytes // len(readers)
        rings = [(*r.geometry(), min(4096, max(4, each // max(1, r.layout.nbytes)))) for r in readers]
        fresh = partial(fresh_array, [(r.layout.shape, r.layout.dtype) for r in readers])
        self.rings = _fastpick.Rings(rings, layout, fresh)
        self.readers = list(readers)
        self.names = list(names)
        self.index = {name: k for k, name in enumerate(self.names)}
        self.joint = _SYNCS.get(settings["sync"])
        self.auto = _WAITS.get(settings["wait"])
        self.tolerance_ns = int(settings["sync_tolerance_ms"] * 1e6)
        self.horizon_ns = int(settings["horizon_ms"] * 1e6)
        self.retired = False  # a ring was replaced: make a new Picker
        self.torn = 0  # copies found torn (the engine answered those requests)
        self._forms: dict[tuple[str, ...] | None, _Form | None] = {}

    def pick(
        self, cameras: Any, op: int, at: Any, sync: Any, wait: Any, copy: bool, now: int = 0
    ) -> tuple[Any, ...] | None:
        """(t_received, t_decided, t_copied, skew_ns, frames, ring indices, names) of a request
        (``now``: when it arrived; 0: now), each frame (slot, seq, frame_id, t_capture, t_stored,
        t_available, generation, ready_at, array or None); None: the engine must answer."""
        try:
            form = self._form(cameras)
        except TypeError:  # cameras that cannot be a key: the engine says why
            return None
        joint = self.joint if sync is None else _SYNCS.get(sync)
        auto = self.auto if wait is None else _WAITS.get(wait)
        if form is None or joint is None or auto is None or type(at) is not int or not _INT64_MIN <= at <= _INT64_MAX:
            return None
        got = self.rings.pick(form[0], form[1], op, at, joint, auto, self.tolerance_ns, self.horizon_ns, copy, now)
        if isinstance(got, int):  # (the reader answers a plain int or a tuple)
            self.retired = self.retired or got == RETIRED
            self.torn += got == TORN
            return None
        return (*got, form[0], form[2])

    def _form(self, cameras: Any) -> _Form | None:
        """(ring indices, ranks by name, names) of a request's cameras (None: all); None if the
        engine must say what is wrong with them."""
        key = cameras if cameras is None or type(cameras) is tuple else tuple(cameras)
        if key in self._forms:
            return self._forms[key]
        names = self.names if key is None else list(key)
        form: _Form | None = None
        if names and all(type(n) is str and n in self.index for n in names) and len(set(names)) == len(names):
            order = sorted(names)
            form = (tuple(self.index[n] for n in names), tuple(order.index(n) for n in names), names)
        if len(self._forms) < _FORMS:
            self._forms[key] = form
        return form
