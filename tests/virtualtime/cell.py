"""A service's sync logic in one process on a virtual clock: virtual cameras (camera.py) writing
real rings, the coordinator's view of them (CameraHandle over RingReader), the request engine and
the streams, run as the coordinator's loop runs them (engine.on_frames and streams.on_frames when
frames are stored, engine.on_tick at its wake-up time). Every decision of an image or tuple request
is also asked of the C twin (_fastpick.decide_near, fxis_shm/core/pickcore.c), which must agree.

    with Cell() as cell:
        cell.camera("a", fps=20)
        cell.camera("b", fps=20, phase_ms=1)
        cell.run_for(2 * SECOND)
        answer = cell.ask(op="tuple", at=t)      # answered in virtual time, however long it waits
"""

from __future__ import annotations

import itertools
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from fxis_shm.core.engine import Failure, Reply, RequestEngine, Schedule, Trigger
from fxis_shm.core.requestdefaults import REQUEST_DEFAULTS
from fxis_shm.core.requeststate import ANSWERED, FAILED, WAITING
from fxis_shm.core.snapshot import SlotMeta, Snapshot
from fxis_shm.errors import Code, ProtocolError
from fxis_shm.service.streams import Streams
from fxis_shm.shm import naming
from fxis_shm.shm.cameras import CameraHandle
from fxis_shm.shm.copyout import CopyOut
from fxis_shm.wire.protocol import request_of

from .camera import MS, Script, VirtualCamera
from .clock import VirtualClock

try:  # imported directly, so that FXIS_PURE_PYTHON=1 still compares the two (tests/unit/test_pickcore.py)
    from fxis_shm.shm import _fastpick
except ImportError as not_built:
    raise ImportError(f"fxis_shm.shm._fastpick is not built ({not_built}): `make setup` builds it") from not_built

SECOND = 1000 * MS
SMALL = {"width": 64, "height": 48}
_NEAR_OPS = ("image", "tuple")
# The state a waiting request is moved to by each decision of the C twin (pickcore.h), as the
# engine moves it by the same decision (fxis_shm.core.requeststate): plan, wait on, or fail.
TWIN_STATES = {_fastpick.PLAN: ANSWERED, _fastpick.WAIT: WAITING, _fastpick.REJECT: FAILED}
_names = itertools.count()


@dataclass
class Answer:
    """What a request got: its frames' slot records (in the order asked) and its reply's body, or
    its error's code and message."""

    request: dict
    asked_at: int
    answered_at: int | None = None
    frames: dict[str, SlotMeta] = field(default_factory=dict)
    tuples: list[dict[str, SlotMeta]] = field(default_factory=list)  # a sequence's, in order
    body: dict = field(default_factory=dict)
    code: str | None = None
    message: str = ""

    @property
    def done(self) -> bool:
        return self.answered_at is not None

    @property
    def skew_ns(self) -> int:
        times = [f.t_capture for f in self.frames.values()]
        return max(times) - min(times)


class Cell:
    def __init__(self, settings: Mapping[str, Any] | None = None, slots: int = 20):
        self.clock = VirtualClock()
        self.origin = self.clock.now_ns()  # the synthetic cameras' shared origin, as a service's
        self.service = f"vt{os.getpid()}x{next(_names)}"
        self.settings = {**REQUEST_DEFAULTS, **(settings or {})}
        self.slots = slots
        self.cameras: dict[str, VirtualCamera] = {}
        self.handles: dict[str, CameraHandle] = {}
        self.engine = RequestEngine(self.handles, self.settings)
        self.streams = Streams(CopyOut(self.handles, self.settings), self._publish)
        self.published: list[tuple[str, dict]] = []  # (topic, header) of every stream message
        self.decisions = 0  # the engine's decisions the C twin was asked about too

    def __enter__(self) -> Cell:
        return self

    def __exit__(self, *exc) -> None:
        for handle in self.handles.values():
            handle.close()
        for cam in self.cameras.values():
            cam.close()
        naming.remove_leftovers(self.service)

    @property
    def now(self) -> int:
        return self.clock.now_ns()

    def camera(self, name: str, script: Script | None = None, lockstep: tuple[float, int] | None = None, **options):
        """A synthetic camera (its options as ``--camera NAME=synthetic:...`` takes them, small
        frames unless said), scripted; ``lockstep``: (hz, phase_ns) of the realtime clock."""
        script, options = script or Script(), {**SMALL, **options}
        cam = VirtualCamera(self.service, name, options, script, self.clock, self.origin, self.slots, lockstep)
        self.cameras[name] = cam
        self.handles[name] = CameraHandle(self.service, name, "synthetic")
        return cam

    # ---- time ----

    def run_until(self, t_end: int, done=lambda: False) -> None:
        """Run every camera and the engine in time order up to ``t_end`` (or until ``done()``)."""
        while not done():
            times = [cam.next_time() for cam in self.cameras.values()] + [self.engine.next_wake()]
            t = min((t for t in times if t is not None), default=None)
            if t is None or t > t_end:
                self.clock.advance_to(max(t_end, self.now))
                return
            self.clock.advance_to(max(t, self.now))
            stored = {name for name, cam in self.cameras.items() if cam.step(self.now)}
            wake = self.engine.next_wake()
            if stored or (wake is not None and wake <= self.now):
                self._carry_out(self.engine.on_frames(stored, self.now))
            if stored:
                self.streams.on_frames(stored, self.now)

    def run_for(self, ns: int) -> None:
        self.run_until(self.now + ns)

    # ---- requests ----

    def ask(self, op: str = "tuple", **request) -> Answer:
        """A request now, checked and completed as the service does (wire.protocol), answered in
        virtual time (the engine's deadline bounds the wait)."""
        answer = Answer(request_of(op, **request), self.now)
        actions = self.engine.submit(answer.request, self.now, answer)
        pending = next((p for p in self.engine.pending if p.ticket is answer), None)
        if pending is not None:
            self.check_twin(pending, "waits")
        self._carry_out(actions)
        self.run_until(self.now + 60 * SECOND, lambda: answer.done)
        assert answer.done, f"{answer.request} got no answer in a virtual minute"
        return answer

    def _carry_out(self, actions: list) -> None:
        """As the coordinator's RequestDispatch.carry_out, with the answers kept."""
        for action in actions:
            if isinstance(action, Trigger):
                for name in action.cameras:
                    self.cameras[name].trigger_now()
            elif isinstance(action, Schedule):
                self._schedule(action)
            elif isinstance(action, Failure):
                answer: Answer = action.pending.ticket
                answer.code, answer.message, answer.answered_at = action.code, action.message, self.now
                if action.code != Code.TIMEOUT:
                    self.check_twin(action.pending, action.code)
            elif isinstance(action, Reply):
                answer = action.pending.ticket
                answer.frames = {c: action.snapshots[c].frame_meta(i) for c, i in action.plan.picks}
                for group in action.plan.groups or ():
                    answer.tuples.append({c: action.snapshots[c].frame_meta(i) for c, i in group})
                answer.body, answer.answered_at = dict(action.plan.body), self.now
                self.check_twin(action.pending, [i for _, i in action.plan.picks], action.snapshots)

    def _schedule(self, action: Schedule) -> None:
        for name in action.cameras:
            try:
                self.cameras[name].trigger_at(action.t)
            except ProtocolError as exc:
                self._carry_out(self.engine.fail(action.pending, exc.code, f"camera {name!r}: {exc.message}"))

    # ---- the C twin ----

    def check_twin(self, pending, outcome, snapshots: Mapping[str, Snapshot] | None = None) -> None:
        """The C twin decides as the engine did: the same frames (``outcome`` a list of indices),
        a wait ("waits") or a refusal (the error code), and so the same state of the request.
        Asked for the requests it decides: image and tuple, sync joint or independent, wait auto
        or none, no camera that captures on a trigger (it does not know them: where it would wait
        for a frame they will not bring, the compiled path leaves the request to the engine, which
        answers from what is stored)."""
        request = pending.request
        sync, wait = (request.get(k) or self.settings[k] for k in ("sync", "wait"))
        if (
            pending.op not in _NEAR_OPS
            or sync not in ("joint", "independent")
            or wait not in ("auto", "none")
            or pending.triggered
            or pending.scheduled
            or any(self.handles[c].triggered for c in pending.cameras)
        ):
            return
        snaps = snapshots or {c: self.handles[c].snapshot() for c in pending.cameras}
        ranks = {name: rank for rank, name in enumerate(sorted(pending.cameras))}
        cams = []
        for name in pending.cameras:
            tl = snaps[name].timeline
            period, delay = self.handles[name].reader.timing()
            cams.append(([tl.at(i) for i in range(len(tl))], ranks[name], period, max(0, delay)))
        max_skew = request.get("max_skew_ms", self.settings["max_skew_ms"])
        decided = _fastpick.decide_near(
            cams,
            pending.t_star,
            self.now,
            int(pending.op == "tuple"),
            int((sync if pending.op == "tuple" else "independent") == "joint"),
            int(wait == "auto"),
            int(request.get("at") is not None),
            int(self.settings["sync_tolerance_ms"] * 1e6),
            -1.0 if max_skew is None else max_skew * 1e6,
        )
        if outcome == "waits":
            assert decided[0] == _fastpick.WAIT, (decided, request)
        elif isinstance(outcome, str):
            assert decided == (_fastpick.REJECT, outcome), (decided, request)
        else:
            skew = pending.ticket.skew_ns if pending.op == "tuple" else 0
            assert decided == (_fastpick.PLAN, tuple(outcome), skew), (decided, outcome, request)
        assert pending.state is TWIN_STATES[decided[0]], (pending.state, decided, request)
        self.decisions += 1

    # ---- streams ----

    def subscribe(self, topic: str) -> None:
        self.streams.subscription(topic, True)

    def _publish(self, topic: str, frames: list) -> None:
        self.published.append((topic, json.loads(bytes(frames[0]))))

    def messages(self, topic: str) -> list[dict]:
        return [header for t, header in self.published if t == topic]
