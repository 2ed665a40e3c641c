"""What ``decide`` does for a capture at T (the request's scheduled cameras) and for a software
trigger, exactly (issue 47): which cameras are waited for, which frame is the scheduled one,
what is answered from storage. Each test states what a user would see."""

from __future__ import annotations

import pytest

from fxis_shm.core.decisions import Context, Plan, Reject, Wait, decide
from fxis_shm.core.engine import Pending
from fxis_shm.core.snapshot import CAPTURE_FREE, CAPTURE_LOCKSTEP, CAPTURE_SCHEDULED, Snapshot
from fxis_shm.core.waitpolicy import AUTO, NONE, CameraState, give_up_time
from fxis_shm.errors import Code
from fxis_shm.wire.protocol import request_of

from .timeline_helpers import MS, CountedReads, snapshot_of

P = 50 * MS  # frame period
DELAY = 2 * MS  # capture to storage
T = 1_000 * MS  # the moment a capture was asked for (t*)
ARRIVED = T - 200 * MS  # when the request came


def free(*times):
    """A free-running camera's ring, frames captured at ``times``."""
    return snapshot_of([(t, 0, CAPTURE_FREE) for t in times], DELAY)


def scheduled_request(cameras, scheduled, wait=AUTO, t_received=ARRIVED) -> tuple[Pending, Context]:
    p = Pending(
        None, request_of("tuple", id=None, cameras=list(cameras), at=T, capture=True), list(cameras), t_received, T
    )
    p.scheduled = frozenset(scheduled)
    return p, Context({c: P for c in cameras}, wait, "joint", 1.0, None, 500)


def states_of(snaps) -> dict[str, CameraState]:
    return {c: CameraState(s.newest, P, DELAY, s.newest_stored) for c, s in snaps.items()}


def at(now, snaps, scheduled, wait=AUTO, t_received=ARRIVED):
    p, context = scheduled_request(list(snaps), scheduled, wait, t_received)
    return decide(p, now, snaps, states_of(snaps), context)


# s: triggered for T, its frame captured 3 ms late (stored 2 ms later); before it, frames captured
# for other requests and free-running ones.
FOR_T = (T + 3 * MS, T, CAPTURE_SCHEDULED)
FOR_ANOTHER = (T - 40 * MS, T - 40 * MS, CAPTURE_SCHEDULED)


def test_the_scheduled_frame_answers_and_the_free_camera_its_frame_nearest_t_star():
    snaps = {"s": snapshot_of([(T - 300 * MS, 0, CAPTURE_FREE), FOR_ANOTHER, FOR_T]), "f": free(T - P, T, T + P)}
    plan = at(T + 100 * MS, snaps, {"s"})
    assert isinstance(plan, Plan) and plan.picks == [("s", 2), ("f", 1)]
    assert plan.body["skew_ns"] == 3 * MS


@pytest.mark.parametrize("frames, index", [([FOR_T], 0), ([FOR_ANOTHER, FOR_T], 1), ([FOR_T, FOR_ANOTHER], 0)])
def test_the_scheduled_frame_is_found_in_any_slot_of_the_ring(frames, index):
    # among frames all stored after the request came; the first slots too
    snaps = {"s": snapshot_of(frames), "f": free(T)}
    assert at(T + 100 * MS, snaps, {"s"}).picks == [("s", index), ("f", 0)]


def test_a_frame_stored_at_the_requests_arrival_may_be_its_frame_one_stored_before_may_not():
    stored_at_arrival = (T + 3 * MS, T, CAPTURE_SCHEDULED, ARRIVED)
    snaps = {"s": snapshot_of([stored_at_arrival]), "f": free(T)}
    assert at(T + 100 * MS, snaps, {"s"}).picks == [("s", 0), ("f", 0)]
    before = {"s": snapshot_of([(T + 3 * MS, T, CAPTURE_SCHEDULED, ARRIVED - 1)]), "f": free(T)}
    assert at(T + 100 * MS, before, {"s"}) == Wait({"s": None}, "the frames awaited from ['s']")


def test_the_scan_for_the_scheduled_frame_stops_at_a_frame_stored_before_the_request():
    # the frame for T sits behind one stored before the request: it is not this request's
    old = (T + 3 * MS, T, CAPTURE_SCHEDULED, ARRIVED - MS)
    snaps = {"s": snapshot_of([old, (T + 20 * MS, 0, CAPTURE_FREE, ARRIVED - 1), (T + 30 * MS, 0, CAPTURE_FREE)])}
    snaps["f"] = free(T)
    assert at(T + 100 * MS, snaps, {"s"}) == Wait({"s": None}, "the frames awaited from ['s']")


@pytest.mark.parametrize(
    "frame",
    [
        (T + 3 * MS, T + P, CAPTURE_SCHEDULED),  # captured for another moment
        (T + 3 * MS, T, CAPTURE_LOCKSTEP),  # on the grid, at T: not triggered for this request
        (T + 3 * MS, T, CAPTURE_FREE),
    ],
)
def test_only_a_frame_scheduled_for_t_star_is_the_scheduled_cameras_frame(frame):
    snaps = {"s": snapshot_of([frame]), "f": free(T)}
    assert at(T + 100 * MS, snaps, {"s"}) == Wait({"s": None}, "the frames awaited from ['s']")


def test_the_free_cameras_are_waited_for_beside_the_scheduled_one_not_the_scheduled_one_by_time():
    # s's frame is there; f's frame nearest T is still to come
    snaps = {"s": snapshot_of([FOR_T]), "f": free(T - 2 * P, T - P)}
    decision = at(T - P + 5 * MS, snaps, {"s"})
    assert decision == Wait({"f": give_up_time(T, states_of(snaps)["f"])}, "the frames awaited from ['f']")


def test_a_scheduled_camera_without_its_frame_waits_until_the_deadline_the_free_ones_are_answered():
    snaps = {"s": snapshot_of([(T - 300 * MS, 0, CAPTURE_FREE)]), "f": free(T - P, T, T + P)}
    assert at(T + 100 * MS, snaps, {"s"}) == Wait({"s": None}, "the frames awaited from ['s']")


def test_a_scheduled_frame_is_never_too_old_for_the_ring_the_free_ones_are_checked():
    # s's frame for T was captured 200 ms late (a loaded machine): its ring's oldest frame is
    # 4 periods after t*, which a free camera's ring would refuse; the reply has it (and f's
    # frame nearest it: joint)
    snaps = {"s": snapshot_of([(T + 200 * MS, T, CAPTURE_SCHEDULED)]), "f": free(T, T + P)}
    plan = at(T + 300 * MS, snaps, {"s"}, wait=NONE)
    assert isinstance(plan, Plan) and plan.picks == [("s", 0), ("f", 1)]
    late_free = {"s": snapshot_of([FOR_T]), "f": free(T + P, T + 2 * P)}  # f holds nothing near T
    with pytest.raises(Reject) as refused:
        at(T + 300 * MS, late_free, {"s"}, wait=NONE)
    assert refused.value.code == Code.OUT_OF_RANGE and "camera 'f'" in refused.value.message


# ---- software triggers ---------------------------------------------------------------------------


def triggered(now, snaps, cameras_triggered, wait=AUTO, at_given=True):
    cameras = list(snaps)
    fields = {"at": T} if at_given else {}
    p = Pending(None, request_of("tuple", id=None, cameras=cameras, **fields), cameras, T, T)
    p.triggered, p.t_trigger = frozenset(cameras_triggered), T
    return decide(p, now, snaps, states_of(snaps), Context({c: P for c in cameras}, wait, "joint", 1.0, None, 500))


def test_a_triggered_camera_is_waited_for_until_a_frame_stored_after_the_trigger_exists():
    snaps = {"t": free(T - 100 * MS), "f": free(T - P, T, T + P)}
    assert triggered(T + 100 * MS, snaps, {"t"}) == Wait({"t": None}, "the frames awaited from ['t']")


def test_a_triggered_frame_is_never_too_old_for_the_ring():
    # t's frame came 300 ms after the trigger (6 periods): answered; f is checked against t*
    snaps = {"t": free(T + 300 * MS), "f": free(T - P, T, T + P)}
    plan = triggered(T + 400 * MS, snaps, {"t"}, wait=NONE)
    assert isinstance(plan, Plan) and plan.picks == [("t", 0), ("f", 2)]


def test_a_ring_not_full_yet_without_the_scheduled_frame_waits_for_it():
    # every frame stored after the request came, none for T, and free slots in the ring
    snaps = {"s": snapshot_of([FOR_ANOTHER, (T + 30 * MS, 0, CAPTURE_FREE)], slots=5), "f": free(T)}
    assert at(T + 100 * MS, snaps, {"s"}) == Wait({"s": None}, "the frames awaited from ['s']")


@pytest.mark.parametrize("stored_from", [0, 1, 3])
def test_the_scan_for_frames_stored_after_the_trigger_ends(stored_from):
    # frames 0 .. 2 stored from `stored_from` on after the trigger (3: none); the decision reads
    # each a few times at most (the scan, the newest frame, the chosen one's grid point): not in a loop
    frames = [(T + k * P, 0, CAPTURE_FREE, T - MS if k < stored_from else T + k * P) for k in range(3)]
    snap = snapshot_of(frames)
    counted = Snapshot(snap.timeline, snap.first_write, CountedReads(snap.rows, limit=8))
    snaps = {"t": counted, "f": free(T, T + P, T + 2 * P)}
    decision = triggered(T + 400 * MS, snaps, {"t"}, wait=NONE)
    if stored_from == 3:
        assert decision == Wait({"t": None}, "the frames awaited from ['t']")
    else:
        assert decision.picks[0] == ("t", stored_from)
