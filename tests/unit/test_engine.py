"""The request engine (fxis_shm.core.engine): requests in, actions out, over camera tables.

The cameras here are tables (TableCamera): the frames a ring would hold, its period
and whether its worker is alive. Each test submits requests and feeds frames and
clock values, and checks what the engine decides: reply now with which frames, wait
until when, or fail with which error.
"""

from __future__ import annotations

import numpy as np
import pytest

from fxis_shm.core.engine import COPY_ATTEMPTS, LIVENESS_CHECK_NS, Failure, Reply, RequestEngine, Schedule, Trigger
from fxis_shm.core.snapshot import CAPTURE_SCHEDULED, SLOT, Snapshot
from fxis_shm.core.timesearch import Timeline
from fxis_shm.core.waitpolicy import CameraState
from fxis_shm.wire.protocol import decode_request, encode_request

from .timeline_helpers import MS

PERIOD = 50 * MS
DELAY = 2 * MS  # capture to storage


class TableCamera:
    """A camera as the engine sees it: a ring of ``slots`` holding the frames added."""

    def __init__(self, slots: int = 20, period_ns: int = PERIOD, triggered: bool = False):
        self.slots = slots
        self.period_ns = period_ns
        self.triggered = triggered
        self.frames: list[tuple[int, ...]] = []  # (t_capture, t_stored, generation, t_target, capture), all written
        self.down: str | None = None
        self.generation = 1

    def add(self, t_capture: int, t_stored: int | None = None, t_target: int = 0, capture: int = 0) -> TableCamera:
        stored = t_capture + DELAY if t_stored is None else t_stored
        self.frames.append((t_capture, stored, self.generation, t_target, capture))
        return self

    def add_periodic(self, first: int, count: int, phase: int = 0) -> TableCamera:
        for k in range(first, first + count):
            self.add(phase + k * self.period_ns)
        return self

    def down_reason(self, now: int) -> str | None:
        return self.down

    def snapshot(self) -> Snapshot:
        count = len(self.frames)
        first = max(0, count - self.slots)
        meta = np.zeros(self.slots, dtype=SLOT)
        for w in range(first, count):
            t_capture, t_stored, generation, t_target, capture = self.frames[w]
            meta[w % self.slots] = (2 * w + 2, w, t_capture, t_stored, t_capture, generation, t_target, capture)
        times = [self.frames[w][0] for w in range(first, count)]  # oldest first, as RingReader gives
        return Snapshot.of_table(Timeline(times, 0, len(times)), first, meta)

    def state(self, snap: Snapshot) -> CameraState:
        n = len(snap.timeline)
        return CameraState(
            newest=snap.newest,
            period_ns=self.period_ns,
            delay_ns=DELAY,
            newest_stored=snap.frame_meta(n - 1).t_stored if n else None,
            triggered=self.triggered,
        )


def request(op: str, **fields) -> dict:
    return decode_request(encode_request(op, id=1, **fields))


def engine_with(**cameras) -> RequestEngine:
    return RequestEngine(cameras)


def only(actions, kind):
    assert len(actions) == 1 and isinstance(actions[0], kind), actions
    return actions[0]


def picked_times(reply: Reply) -> dict[str, int]:
    """Capture time of each camera's chosen frame."""
    return {cam: reply.snapshots[cam].timeline.at(i) for cam, i in reply.plan.picks}


# ---- answering at once, and waiting ----


@pytest.mark.parametrize(
    "t_star, answered_now, expected",
    [
        (10 * PERIOD, True, 10 * PERIOD),  # a stored frame is exactly t*
        (10 * PERIOD + PERIOD // 2 - 1, True, 10 * PERIOD),  # the stored frame stays the nearest
        (19 * PERIOD + 1, True, 19 * PERIOD),
        # halfway to a frame not stored yet: it may be nearer only by its jitter, so the stored
        # one answers at once (issue 41: waiting a period for it, the stored one often won anyway)
        (19 * PERIOD + PERIOD // 2, True, 19 * PERIOD),
        (19 * PERIOD + PERIOD // 2 + MS, False, 20 * PERIOD),  # nearer by the sync tolerance (2 ms): wait
        (21 * PERIOD, False, 21 * PERIOD),  # the future
    ],
)
def test_image_waits_exactly_when_a_nearer_frame_is_coming(t_star, answered_now, expected):
    cam = TableCamera().add_periodic(0, 20)  # frames at 0 .. 19 periods
    engine = engine_with(cam=cam)
    now = 19 * PERIOD + DELAY + 1
    actions = engine.submit(request("image", camera="cam", at=t_star), now, "ticket")
    if not answered_now:
        assert actions == [] and len(engine.pending) == 1
        while not actions:  # the camera goes on; the engine hears of each frame
            cam.add_periodic(len(cam.frames), 1)
            now = cam.frames[-1][1]
            actions = engine.on_frames({"cam"}, now)
    reply = only(actions, Reply)
    assert reply.pending.ticket == "ticket"
    assert picked_times(reply) == {"cam": expected}
    assert engine.pending == []


def test_the_papers_spike_case_gives_the_least_skewed_tuple():
    """t* halfway between frames of two cameras 3 ms apart: the paper's per-camera search
    picks frames a period apart (the spike); joint selection keeps them 3 ms apart."""
    a = TableCamera().add_periodic(0, 20)
    b = TableCamera().add_periodic(0, 20, phase=3 * MS)
    t_star = 10 * PERIOD + PERIOD // 2 + 1 * MS  # nearer a's frame 11, b's frame 10
    now = 20 * PERIOD
    engine = engine_with(a=a, b=b)
    independent = only(engine.submit(request("tuple", at=t_star, sync="independent"), now, 1), Reply)
    joint = only(engine.submit(request("tuple", at=t_star), now, 2), Reply)
    assert picked_times(independent) == {"a": 11 * PERIOD, "b": 10 * PERIOD + 3 * MS}
    assert independent.plan.body["skew_ns"] == PERIOD - 3 * MS
    assert joint.plan.body["skew_ns"] == 3 * MS


def test_a_request_for_now_waits_for_no_frame_when_the_stored_one_is_nearest():
    cam = TableCamera().add_periodic(0, 20)
    engine = engine_with(cam=cam)
    now = 19 * PERIOD + PERIOD // 2 - 1  # a hair before halfway to the next frame
    reply = only(engine.submit(request("tuple"), now, 1), Reply)
    assert picked_times(reply) == {"cam": 19 * PERIOD}
    assert reply.plan.body["t_request"] == now


def test_next_waits_for_a_frame_stored_after_arrival():
    cam = TableCamera().add_periodic(0, 20)
    engine = engine_with(cam=cam)
    now = 19 * PERIOD + DELAY + 1
    assert engine.submit(request("tuple", wait="next", at=10 * PERIOD), now, 1) == []
    cam.add_periodic(20, 1)
    reply = only(engine.on_frames({"cam"}, 20 * PERIOD + DELAY), Reply)
    assert picked_times(reply) == {"cam": 10 * PERIOD}  # still the nearest to t*, now allowed


def test_none_never_waits():
    cam = TableCamera().add_periodic(0, 20)
    engine = engine_with(cam=cam)
    reply = only(
        engine.submit(request("image", camera="cam", at=25 * PERIOD, wait="none"), 19 * PERIOD + DELAY, 1), Reply
    )
    assert picked_times(reply) == {"cam": 19 * PERIOD}


def test_frames_of_other_cameras_do_not_wake_a_request():
    a, b = TableCamera().add_periodic(0, 20), TableCamera().add_periodic(0, 20)
    engine = engine_with(a=a, b=b)
    now = 19 * PERIOD + DELAY
    engine.submit(request("image", camera="a", at=21 * PERIOD), now, 1)
    b.add_periodic(20, 1)
    assert engine.on_frames({"b"}, now + 1) == [] and len(engine.pending) == 1


# ---- the wake-up time, deadlines and give-ups ----


def test_a_waiting_request_wakes_for_liveness_and_times_out_at_its_deadline():
    cam = TableCamera().add_periodic(0, 20)
    engine = engine_with(cam=cam)
    now = 19 * PERIOD + DELAY
    t_star = 19 * PERIOD + 300 * MS  # 300 ms ahead: waits for frames that never come
    assert engine.submit(request("image", camera="cam", at=t_star, timeout_ms=100), now, 1) == []
    assert engine.next_wake() == now + LIVENESS_CHECK_NS
    deadline = t_star + 100 * MS
    t = now
    while True:
        t = engine.next_wake()
        actions = engine.on_tick(t)
        if actions:
            break
        assert t < deadline
    failure = only(actions, Failure)
    assert t == deadline and failure.code == "TIMEOUT"
    assert "did not arrive within 100 ms" in failure.message


def test_a_dropped_frame_is_given_up_on_and_the_stored_one_answers():
    cam = TableCamera().add_periodic(0, 20)
    engine = engine_with(cam=cam)
    t_star = 20 * PERIOD - 5 * MS  # frame 20 is the nearest, but it is dropped; 19 beats 21
    assert engine.submit(request("image", camera="cam", at=t_star), 19 * PERIOD + DELAY, 1) == []
    give_up = engine.next_wake()
    assert give_up == 20 * PERIOD + PERIOD + DELAY  # overdue: a period of slack after storage was due
    assert engine.on_tick(give_up - 1) == []
    reply = only(engine.on_tick(give_up), Reply)
    assert picked_times(reply) == {"cam": 19 * PERIOD}


def test_a_request_too_far_in_the_future_is_refused():
    engine = engine_with(cam=TableCamera().add_periodic(0, 20))
    failure = only(engine.submit(request("image", camera="cam", at=60_000 * MS), 0, 1), Failure)
    assert failure.code == "OUT_OF_RANGE" and "horizon" in failure.message


def test_a_request_older_than_the_ring_is_refused_with_what_it_holds():
    engine = engine_with(cam=TableCamera(slots=5).add_periodic(0, 20))  # holds frames 15..19
    failure = only(engine.submit(request("image", camera="cam", at=10 * PERIOD), 20 * PERIOD, 1), Failure)
    assert failure.code == "OUT_OF_RANGE" and "its ring holds 5 frames" in failure.message


# ---- cameras that are down, unknown, empty ----


def test_a_dead_camera_fails_waiting_requests_at_the_next_look():
    cam = TableCamera().add_periodic(0, 20)
    engine = engine_with(cam=cam)
    now = 19 * PERIOD + DELAY
    assert engine.submit(request("image", camera="cam", at=19 * PERIOD + 40 * MS), now, 1) == []
    cam.down = "camera 'cam' is down: its worker is not running"
    failure = only(engine.on_tick(engine.next_wake()), Failure)
    assert failure.code == "CAMERA_DOWN" and "not running" in failure.message
    assert engine.pending == []


def test_partial_leaves_out_the_cameras_that_are_down():
    a, b = TableCamera().add_periodic(0, 20), TableCamera().add_periodic(0, 20)
    b.down = "camera 'b' is down"
    engine = engine_with(a=a, b=b)
    reply = only(engine.submit(request("tuple", at=10 * PERIOD, partial=True), 20 * PERIOD, 1), Reply)
    assert reply.pending.cameras == ["a"] and reply.plan.body["missing"] == ["b"]
    a.down = "camera 'a' is down"
    failure = only(engine.submit(request("tuple", at=10 * PERIOD, partial=True), 20 * PERIOD, 2), Failure)
    assert failure.code == "CAMERA_DOWN" and "every requested camera is down" in failure.message


def test_unknown_cameras_are_named():
    engine = engine_with(cam=TableCamera().add_periodic(0, 3))
    failure = only(engine.submit(request("tuple", cameras=["cam", "nope"]), 0, 1), Failure)
    assert failure.code == "UNKNOWN_CAMERA" and "'nope'" in failure.message and "['cam']" in failure.message


def test_latest_from_an_empty_ring_says_so():
    engine = engine_with(cam=TableCamera())
    failure = only(engine.submit(request("latest"), 0, 1), Failure)
    assert failure.code == "NO_FRAMES"


def test_a_camera_with_no_frame_yet_is_waited_for():
    cam = TableCamera()
    engine = engine_with(cam=cam)
    assert engine.submit(request("tuple"), 0, 1) == []
    cam.add(10 * MS)
    reply = only(engine.on_frames({"cam"}, 10 * MS + DELAY), Reply)
    assert picked_times(reply) == {"cam": 10 * MS}


# ---- restarts and overwritten copies ----


def test_a_restarted_camera_is_followed():
    cam = TableCamera().add_periodic(0, 20)
    engine = engine_with(cam=cam)
    t_star = 19 * PERIOD + 40 * MS
    assert engine.submit(request("image", camera="cam", at=t_star), 19 * PERIOD + DELAY, 1) == []
    cam.generation = 2  # the worker came back: its frames carry a new generation
    cam.add(19 * PERIOD + 41 * MS)
    reply = only(engine.on_frames({"cam"}, 19 * PERIOD + 41 * MS + DELAY), Reply)
    ((cam_name, index),) = reply.plan.picks
    assert reply.snapshots[cam_name].frame_meta(index).generation == 2


def test_an_overwritten_copy_is_planned_again_then_given_up():
    cam = TableCamera().add_periodic(0, 20)
    engine = engine_with(cam=cam)
    reply = only(engine.submit(request("latest"), 20 * PERIOD, 1), Reply)
    for _ in range(COPY_ATTEMPTS - 1):
        cam.add_periodic(len(cam.frames), 1)  # the copy lost the race: the ring moved on
        again = only(engine.retry(reply, 21 * PERIOD), Reply)
        assert picked_times(again)["cam"] > picked_times(reply)["cam"]
        reply = again
    failure = only(engine.retry(reply, 22 * PERIOD), Failure)
    assert failure.code == "OVERRUN" and "overwritten" in failure.message and "--history" in failure.message


# ---- triggers, limits, sequences ----


def test_a_triggered_camera_answers_with_the_frame_after_the_trigger():
    trig, free = TableCamera(triggered=True).add(5 * MS), TableCamera().add_periodic(0, 20)
    engine = engine_with(trig=trig, free=free)
    now = 19 * PERIOD + DELAY
    actions = engine.submit(request("tuple"), now, 1)
    assert actions == [Trigger(("trig",))]
    trig.add(now + 1 * MS, now + 3 * MS)
    reply = only(engine.on_frames({"trig"}, now + 3 * MS), Reply)
    assert picked_times(reply)["trig"] == now + 1 * MS


def test_a_past_moment_on_triggered_cameras_that_stored_nothing_is_refused_at_once():
    engine = engine_with(a=TableCamera(triggered=True), b=TableCamera(triggered=True))
    now = 1000 * MS
    failure = only(engine.submit(request("tuple", at=now - MS), now, 1), Failure)
    assert failure.code == "NO_FRAMES" and engine.pending == []
    assert "['a', 'b'] capture only on a trigger" in failure.message and "1.0 ms past" in failure.message
    assert "capture=True" in failure.message  # what to do instead


def test_a_past_moment_on_triggered_cameras_is_answered_from_the_stored_frames_at_once():
    # after captures at T 1.1 s apart, the measured "period" is that spacing (fxis status said
    # "set fps 0.9"), and a t* 1 ms ago waited for the frame it predicted until its timeout
    apart = 1100 * MS
    a, b = TableCamera(period_ns=apart, triggered=True), TableCamera(period_ns=apart, triggered=True)
    for cam in (a, b):
        cam.add(1000 * MS, t_target=1000 * MS, capture=CAPTURE_SCHEDULED)
        cam.add(2100 * MS, t_target=2100 * MS, capture=CAPTURE_SCHEDULED)
    engine = engine_with(a=a, b=b)
    now = 3000 * MS
    reply = only(engine.submit(request("tuple", at=now - MS), now, 1), Reply)
    assert picked_times(reply) == {"a": 2100 * MS, "b": 2100 * MS}
    image = only(engine.submit(request("image", camera="a", at=1500 * MS), now, 2), Reply)
    assert picked_times(image) == {"a": 1000 * MS}


def test_the_per_client_limit_refuses_the_next_waiting_request():
    engine = RequestEngine({"cam": TableCamera().add_periodic(0, 20)}, {"max_pending_per_client": 2})
    future = request("image", camera="cam", at=25 * PERIOD)
    for n in range(2):
        assert engine.submit(future, 20 * PERIOD, n, client=b"c1") == []
    failure = only(engine.submit(future, 20 * PERIOD, 3, client=b"c1"), Failure)
    assert failure.code == "BUSY"
    assert engine.submit(future, 20 * PERIOD, 4, client=b"c2") == []  # another client may still wait


def test_a_consecutive_sequence_after_t_star_waits_for_every_frame():
    a, b = TableCamera().add_periodic(0, 20), TableCamera().add_periodic(0, 20, phase=1 * MS)
    engine = engine_with(a=a, b=b)
    t_star = 19 * PERIOD + 10 * MS
    assert (
        engine.submit(
            request("sequence", kind="consecutive", count=3, direction="after", at=t_star),
            19 * PERIOD + DELAY + 1 * MS,
            1,
        )
        == []
    )
    actions = []
    for k in range(20, 24):
        a.add_periodic(k, 1)
        b.add_periodic(k, 1, phase=1 * MS)
        actions = engine.on_frames({"a", "b"}, k * PERIOD + 1 * MS + DELAY)
        if actions:
            break
    reply = only(actions, Reply)
    assert reply.plan.body["targets"] == [20 * PERIOD, 21 * PERIOD, 22 * PERIOD]
    assert [[reply.snapshots[c].timeline.at(i) for c, i in g] for g in reply.plan.groups] == [
        [k * PERIOD, k * PERIOD + 1 * MS] for k in (20, 21, 22)
    ]


def test_a_sequence_larger_than_the_limit_is_refused():
    engine = RequestEngine({"cam": TableCamera().add_periodic(0, 20)}, {"max_sequence_frames": 4})
    failure = only(
        engine.submit(request("sequence", kind="interval", camera="cam", count=5, interval_ms=-10), 20 * PERIOD, 1),
        Failure,
    )
    assert failure.code == "TOO_LARGE"


def test_the_coordinator_and_same_host_clients_decide_with_this_one_engine():
    """One implementation of selection and waiting: both callers hand requests to the engine
    and hold no selection or wait-policy function of their own."""
    from fxis_shm.client import localreads
    from fxis_shm.core import engine
    from fxis_shm.service import coordinator

    deciding = (
        "fxis_shm.core.selection",
        "fxis_shm.core.waitpolicy",
        "fxis_shm.core.decisions",
        "fxis_shm.core.timesearch",
    )
    for caller in (coordinator, localreads):
        assert caller.RequestEngine is engine.RequestEngine
        own = [name for name, value in vars(caller).items() if getattr(value, "__module__", None) in deciding]
        assert own == [], f"{caller.__name__} decides by itself with {own}"


# ---- capture at T ----


def test_a_capture_at_t_schedules_the_triggered_cameras_and_waits_for_their_frames_for_t():
    trig, free = TableCamera(triggered=True).add(5 * MS), TableCamera().add_periodic(0, 20)
    engine = engine_with(trig=trig, free=free)
    now, at = 19 * PERIOD + DELAY, 22 * PERIOD + 7 * MS
    actions = engine.submit(request("tuple", at=at, capture=True), now, "ticket")
    schedule = only(actions, Schedule)
    assert (schedule.cameras, schedule.t) == (("trig",), at) and schedule.pending is engine.pending[0]
    free.add_periodic(20, 4)  # the free camera passes T
    trig.add(at - 40 * MS, t_stored=now + 1)  # a frame triggered "now" meanwhile: not the one for T
    trig.add(at + 20_000, t_stored=now + 2, t_target=at - 1, capture=CAPTURE_SCHEDULED)  # another T's
    assert engine.on_frames({"trig", "free"}, at + 10 * MS) == []
    trig.add(at + 30_000, t_target=at, capture=CAPTURE_SCHEDULED)
    reply = only(engine.on_frames({"trig"}, at + DELAY + 30_000), Reply)
    assert picked_times(reply) == {"trig": at + 30_000, "free": 22 * PERIOD}  # free: its frame nearest T


def test_a_capture_with_no_camera_to_trigger_answers_with_the_frames_nearest_t():
    free = TableCamera().add_periodic(0, 20)
    engine = engine_with(free=free)
    at = 21 * PERIOD + 3 * MS
    assert engine.submit(request("image", camera="free", at=at, capture=True), 19 * PERIOD + DELAY, 1) == []
    free.add_periodic(20, 3)
    assert picked_times(only(engine.on_frames({"free"}, 22 * PERIOD + DELAY), Reply)) == {"free": 21 * PERIOD}


def test_a_capture_in_the_past_is_refused_and_a_refused_schedule_fails_its_request():
    trig = TableCamera(triggered=True).add(5 * MS)
    engine = engine_with(trig=trig)
    failure = only(engine.submit(request("image", camera="trig", at=10 * MS, capture=True), 20 * MS, 1), Failure)
    assert failure.code == "OUT_OF_RANGE" and "10.0 ms in the past" in failure.message
    schedule = only(engine.submit(request("image", camera="trig", at=500 * MS, capture=True), 20 * MS, 2), Schedule)
    failed = only(engine.fail(schedule.pending, "OUT_OF_RANGE", "too near"), Failure)
    assert (failed.pending.ticket, failed.message) == (2, "too near") and engine.pending == []
    assert engine.fail(schedule.pending, "OUT_OF_RANGE", "again") == []  # answered once
