"""The request engine: one owner for every request, from arrival to reply, with no I/O.

The coordinator (and any reader of the rings that answers requests itself) hands
it what happens and carries out what it returns::

    actions = engine.submit(request, now, ticket)   # a request arrived
    actions = engine.on_frames({"cam0"}, now)        # cameras stored frames
    actions = engine.on_tick(now)                   # engine.next_wake() has passed

An action is a ``Trigger`` (fire these software triggers now), a ``Reply`` (copy
these frames out and reply; should a copy find its slot overwritten, hand the plan
to ``engine.retry``) or a ``Failure`` (reply with this error). Whether a request
must wait is decided in one place, ``decide`` (fxis_shm.core.decisions), from one look
at each camera, and the selection that decides it is the one the reply carries. Each
request's life is a named state, moved only along the table of fxis_shm.core.requeststate
(which also says what a failure does to it).

Pure: cameras are read through the ``CameraSource`` protocol, and the clock is an
integer passed in.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from fxis_shm.core import sequences
from fxis_shm.core.decisions import Context, Plan, Reject, Wait, check_size, decide, newest_frames, sequence_spec
from fxis_shm.core.requestdefaults import REQUEST_DEFAULTS
from fxis_shm.core.requeststate import (
    ANSWERED,
    CANCELLED,
    FAILED,
    RECEIVED,
    WAITING_STATES,
    RequestState,
    checked_move,
    waiting_state,
)
from fxis_shm.core.snapshot import Snapshot
from fxis_shm.core.waitpolicy import CameraState, never_coming
from fxis_shm.errors import Code

log = logging.getLogger("engine")

LIVENESS_CHECK_NS = 100_000_000  # waiting requests notice a dead camera this fast
COPY_ATTEMPTS = 3  # plans made again after a chosen slot was overwritten during the copy
OVERRUN_MESSAGE = (
    f"frames were overwritten {COPY_ATTEMPTS} times while being copied: the ring came round faster than "
    "this reader copies (give the camera more slots or a longer --history, or ask for newer frames)"
)
FRAME_OPS = ("image", "tuple", "latest", "sequence")


class CameraSource(Protocol):
    """What the engine reads of one camera (the coordinator's CameraHandle, or a test's table)."""

    def down_reason(self, now: int) -> str | None: ...

    def snapshot(self) -> Snapshot: ...

    def state(self, snapshot: Snapshot) -> CameraState: ...

    @property
    def period_ns(self) -> int: ...

    @property
    def triggered(self) -> bool: ...

    @property
    def slots(self) -> int | None: ...


@dataclass
class Pending:
    """A request on its way to a reply. ``ticket`` is the caller's: where the reply goes.
    ``state`` changes only through ``move`` (the moves fxis_shm.core.requeststate allows)."""

    ticket: Any
    request: dict[str, Any]
    cameras: list[str]
    t_received: int
    t_star: int
    client: Any = None  # who asked, for the per-client limit
    local: bool = False  # the client shares our kernel: reply with where the frames are
    deadline: int = 0
    wake_at: int = 0
    ready_at: dict[str, int] = field(default_factory=dict)  # when each camera's frame was there
    missing: list[str] = field(default_factory=list)  # cameras down, left out of a partial tuple
    triggered: frozenset[str] = frozenset()  # software-triggered cameras this request triggered
    t_trigger: int | None = None
    scheduled: frozenset[str] = frozenset()  # cameras triggered for a capture at t* (capture=True)
    attempts: int = 0  # plans made for it
    state: RequestState = RECEIVED

    def move(self, to: RequestState) -> None:
        """Become ``to``; IllegalMove if the state table does not allow it."""
        self.state = checked_move(self.state, to)

    def wait(self) -> None:
        """Wait (again) the way its admission chose; no move if it waits so already."""
        to = waiting_state(self.triggered, self.scheduled)
        if self.state is not to:
            self.move(to)

    @property
    def op(self) -> str:
        return str(self.request["op"])

    @property
    def id(self) -> Any:
        return self.request.get("id")


@dataclass(frozen=True)
class Trigger:
    cameras: tuple[str, ...]


@dataclass(frozen=True)
class Schedule:
    """Have ``cameras`` triggered for a capture at ``t`` (service clock); a refusal fails ``pending``."""

    pending: Pending
    cameras: tuple[str, ...]
    t: int


@dataclass(frozen=True)
class Failure:
    pending: Pending
    code: str
    message: str


@dataclass(frozen=True)
class Reply:
    """Copy ``plan``'s frames out of ``snapshots`` and reply to ``pending``."""

    pending: Pending
    plan: Plan
    snapshots: dict[str, Snapshot]
    t_decided: int


Action = Trigger | Schedule | Failure | Reply


class RequestEngine:
    def __init__(self, cameras: Mapping[str, CameraSource], settings: Mapping[str, Any] | None = None):
        self.cameras = cameras
        self.settings = {**REQUEST_DEFAULTS, **(settings or {})}
        self.pending: list[Pending] = []

    # ---- what happens ----

    def submit(
        self, request: dict[str, Any], now: int, ticket: Any, client: Any = None, local: bool = False
    ) -> list[Action]:
        """A request for frames (op image, tuple, latest or sequence) arrived at ``now``."""
        p = Pending(ticket, request, [], now, now, client=client, local=local)
        actions: list[Action] = []
        try:
            self._admit(p, now, actions)
        except Reject as exc:
            return [failure(p, exc.code, exc.message)]
        p.wait()
        if not self._evaluate(p, now, actions):
            self.pending.append(p)
        return actions

    def on_frames(self, cameras: set[str] | frozenset[str], now: int) -> list[Action]:
        """``cameras`` stored frames: evaluate the requests waiting for them, and those due."""
        actions: list[Action] = []
        still = []
        for p in self.pending:
            due = p.wake_at <= now or not cameras.isdisjoint(p.cameras)
            if not (due and self._evaluate(p, now, actions)):
                still.append(p)
        self.pending = still
        return actions

    def on_tick(self, now: int) -> list[Action]:
        """Evaluate the requests whose wake-up time has come."""
        return self.on_frames(frozenset(), now)

    def retry(self, reply: Reply, now: int) -> list[Action]:
        """A chosen slot was overwritten while ``reply`` was being copied: plan again (it may
        also wait again, or fail). IllegalMove if ``reply``'s request is not ANSWERED."""
        p = reply.pending
        if p.attempts >= COPY_ATTEMPTS:
            return [failure(p, Code.OVERRUN, OVERRUN_MESSAGE)]
        actions: list[Action] = []
        if not self._evaluate(p, now, actions):
            p.wait()
            self.pending.append(p)
        return actions

    def fail(self, p: Pending, code: str, message: str) -> list[Action]:
        """Fail a waiting request (its capture could not be scheduled); nothing if it is not
        waiting (answered, failed or cancelled already)."""
        if p.state not in WAITING_STATES:
            return []
        self.pending = [q for q in self.pending if q is not p]
        return [failure(p, code, message)]

    def cancel_all(self) -> None:
        """Forget every waiting request (their caller gave up on them): each is CANCELLED."""
        for p in self.pending:
            p.move(CANCELLED)
        self.pending.clear()

    def next_wake(self) -> int | None:
        """The earliest moment a waiting request wants to be evaluated again."""
        return min((p.wake_at for p in self.pending), default=None)

    def busy(self, client: Any = None) -> str | None:
        """Why a request of ``client`` would be refused now (BUSY: the limits on waiting
        requests, in all and per client); None if it would be admitted."""
        if len(self.pending) >= self.settings["max_pending"]:
            return f"{len(self.pending)} requests are waiting already; try again"
        limit = self.settings["max_pending_per_client"]
        if client is not None and sum(q.client == client for q in self.pending) >= limit:
            return f"this client has {limit} requests waiting already (the limit)"
        return None

    def setting(self, request: dict[str, Any], key: str) -> Any:
        value = request.get(key)
        return self.settings[key] if value is None else value

    # ---- admission ----

    def _admit(self, p: Pending, now: int, actions: list[Action]) -> None:
        request = p.request
        p.cameras = self._cameras_of(request)
        busy = self.busy(p.client)
        if busy:
            raise Reject(Code.BUSY, busy)
        if request.get("partial"):  # leave out the cameras that are down, and say which
            p.missing = [c for c in p.cameras if self.cameras[c].down_reason(now)]
            p.cameras = [c for c in p.cameras if c not in p.missing]
            if not p.cameras:
                raise Reject(Code.CAMERA_DOWN, f"every requested camera is down: {p.missing}")
        if request.get("at") is not None:
            p.t_star = request["at"]
        elif request.get("t_call") is not None:  # the moment of the call: the request's travel time removed
            p.t_star = min(request["t_call"], p.t_star)
        latest = self._latest_needed(p)
        horizon_ms = self.settings["horizon_ms"]
        if latest - now > horizon_ms * 1e6:
            raise Reject(
                Code.OUT_OF_RANGE,
                f"the request needs frames {(latest - now) / 1e6:.1f} ms in the future; the horizon is {horizon_ms} ms",
            )
        if p.op == "sequence":
            self._check_sequence(p)
        p.deadline = max(now, latest) + int(self.setting(request, "timeout_ms") * 1e6)
        if request.get("capture"):
            self._schedule(p, now, actions)
        elif p.op in ("image", "tuple") and request.get("at") is None:
            triggered = tuple(c for c in p.cameras if self.cameras[c].slots and self.cameras[c].triggered)
            if triggered:  # t* is the trigger: now
                p.t_trigger = p.t_star = now
                p.triggered = frozenset(triggered)
                actions.append(Trigger(triggered))

    def _schedule(self, p: Pending, now: int, actions: list[Action]) -> None:
        """A capture at t*: the cameras that can be triggered are, for t*; the others answer
        with their frames nearest t*."""
        if p.t_star < now:
            raise Reject(
                Code.OUT_OF_RANGE,
                f"T is {(now - p.t_star) / 1e6:.1f} ms in the past: a capture can only be scheduled ahead",
            )
        scheduled = tuple(c for c in p.cameras if self.cameras[c].triggered)
        if scheduled:
            p.scheduled = frozenset(scheduled)
            actions.append(Schedule(p, scheduled, p.t_star))

    def _cameras_of(self, request: dict[str, Any]) -> list[str]:
        if request.get("camera") is not None:
            names = [request["camera"]]
        else:
            names = request.get("cameras") or list(self.cameras)
        unknown = [n for n in names if n not in self.cameras]
        if unknown:
            raise Reject(Code.UNKNOWN_CAMERA, f"unknown camera(s) {unknown}; this service has {sorted(self.cameras)}")
        return names

    def _latest_needed(self, p: Pending) -> int:
        """The latest capture time the request needs frames up to (periods not yet counted)."""
        if p.op != "sequence":
            return p.t_star
        return sequences.latest_needed(sequence_spec(p.request, p.t_star), 0)

    def _check_sequence(self, p: Pending) -> None:
        r = p.request
        if r["count"] is None:
            return
        check_size(r["count"] * len(p.cameras), self.settings["max_sequence_frames"])
        slots = min((s for s in (self.cameras[c].slots for c in p.cameras) if s), default=None)
        if r["kind"] == sequences.CONSECUTIVE and slots is not None and r["count"] >= slots:
            # the oldest slot is always the next one overwritten: one fewer is guaranteed
            raise Reject(
                Code.OUT_OF_RANGE,
                f"asks for {r['count']} consecutive frames; rings of {slots} slots "
                f"hold at most {slots - 1} consecutive frames that can always be read",
            )

    # ---- evaluation ----

    def _evaluate(self, p: Pending, now: int, actions: list[Action]) -> bool:
        """Reply to ``p`` if it can be answered now (adding the action); True once it is done."""
        try:
            snaps = self._snapshots(p, now)
            if p.op == "latest":  # never waits, chooses nothing: no camera state or settings needed
                decision: Wait | Plan = newest_frames(p.cameras, snaps)
            else:
                states = {c: self.cameras[c].state(snaps[c]) for c in p.cameras}
                if p.request.get("at") is not None and not p.scheduled:
                    refuse_never_coming(p.t_star, now, states)
                decision = decide(p, now, snaps, states, self._context(p))
            for cam in p.cameras:
                if not isinstance(decision, Wait) or cam not in decision.until:
                    # ready now, or when a frame that raced the request landed
                    p.ready_at.setdefault(cam, max(now, snaps[cam].newest_stored or now))
            if isinstance(decision, Plan):
                p.attempts += 1
                p.move(ANSWERED)
                actions.append(Reply(p, decision, snaps, now))
                return True
            if now >= p.deadline:
                waited = (p.deadline - max(p.t_received, p.t_star)) / 1e6
                raise Reject(Code.TIMEOUT, f"{decision.reason} did not arrive within {waited:.0f} ms")
            give_ups = [t for t in decision.until.values() if t is not None]
            p.wake_at = min(p.deadline, now + LIVENESS_CHECK_NS, *give_ups)
            return False
        except Reject as exc:
            actions.append(failure(p, exc.code, exc.message))
        except Exception as bug:  # a bug must not take the service down
            # (a name of its own: compiled, ``exc`` above is typed Reject, and another exception
            # bound to it raised TypeError out of the engine)
            log.exception("internal error on %s", p.op)
            actions.append(failure(p, Code.INTERNAL, repr(bug)))
        return True

    def _snapshots(self, p: Pending, now: int) -> dict[str, Snapshot]:
        snaps = {}
        for cam in p.cameras:
            source = self.cameras[cam]
            reason = source.down_reason(now)
            if reason:
                raise Reject(Code.CAMERA_DOWN, reason)
            snaps[cam] = source.snapshot()
        return snaps

    def _context(self, p: Pending) -> Context:
        return Context(
            periods={c: self.cameras[c].period_ns for c in p.cameras},
            wait=self.setting(p.request, "wait"),
            sync=self.setting(p.request, "sync"),
            sync_tolerance_ms=self.settings["sync_tolerance_ms"],
            max_skew_ms=self.setting(p.request, "max_skew_ms"),
            max_sequence_frames=self.settings["max_sequence_frames"],
        )


def failure(p: Pending, code: str, message: str) -> Failure:
    """Every failure of a request goes through here: it becomes FAILED, for good, and its
    caller gets this one Failure to reply with (fxis_shm.core.requeststate)."""
    p.move(FAILED)
    return Failure(p, code, message)


def refuse_never_coming(t_star: int, now: int, states: Mapping[str, CameraState]) -> None:
    """A t* already past on cameras that capture only on a trigger and have stored nothing:
    no frame will come for it, so the request is refused now rather than at its timeout."""
    cameras = never_coming(t_star, now, states)
    if cameras:
        raise Reject(
            Code.NO_FRAMES,
            f"camera(s) {cameras} capture only on a trigger (trigger=software) and have stored no frame: "
            f"none will come for a moment {(now - t_star) / 1e6:.1f} ms past; ask for a moment ahead "
            "with capture=True, or without a moment to trigger them now",
        )
