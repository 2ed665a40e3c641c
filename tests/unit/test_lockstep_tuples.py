"""Tuples of lockstep frames are of one grid point, or say they are not (issue 41): the selection
(fxis_shm.core.selection.on_grid), the reply ``decide`` builds (``grid_mismatch``), and what a
client reads of it (``FrameTuple.grid_mismatch``, in the caller's clock)."""

from __future__ import annotations

import numpy as np
import pytest

from fxis_shm.client.frames import in_caller_clock, sequence_of, tuple_of
from fxis_shm.core.clockmap import ClockEstimate
from fxis_shm.core.decisions import Context, Plan, Reject, decide
from fxis_shm.core.engine import Pending
from fxis_shm.core.selection import INDEPENDENT, JOINT, Selection, on_grid, select_joint
from fxis_shm.core.snapshot import CAPTURE_FREE, CAPTURE_LOCKSTEP, Snapshot
from fxis_shm.core.waitpolicy import NONE, CameraState
from fxis_shm.errors import Code
from fxis_shm.wire.protocol import request_of

from .timeline_helpers import MS, ring, snapshot_of

P = 50 * MS  # a 20 Hz grid
G = 1_000 * MS  # a grid point: the others are G + k P


def lockstep(frames, capture=CAPTURE_LOCKSTEP) -> Snapshot:
    """A ring of frames ``(t_capture, grid point)``, oldest first, stored 2 ms after capture."""
    return snapshot_of([(t, point, capture) for t, point in frames])


def tuple_reply(snaps, t_star, sync=JOINT, max_skew_ms=None, tolerance_ms=1.0) -> Plan:
    names = list(snaps)
    p = Pending(None, request_of("tuple", id=None, cameras=names, at=t_star), names, t_star + 500 * MS, t_star)
    states = {c: CameraState(s.newest, P, 2 * MS, s.newest_stored) for c, s in snaps.items()}
    context = Context({c: P for c in names}, NONE, sync, tolerance_ms, max_skew_ms, 500)
    decision = decide(p, t_star + 500 * MS, snaps, states, context)
    assert isinstance(decision, Plan)
    return decision


def picked(plan: Plan, snaps) -> dict[str, int]:
    """Each camera's chosen frame, by its capture time."""
    return {c: snaps[c].timeline.at(i) for c, i in plan.picks}


# Issue 41's case (tests/unit/test_selection.py has it without grid points): both cameras captured
# G 15 ms late, right missed G + P and G + 2P; t* 1070 ms.
ISSUE_41 = {
    "left": lockstep([(G + 15_200_000, G), (G + P, G + P), (G + 2 * P, G + 2 * P)]),
    "right": lockstep([(G + 15_700_000, G), (G + 3 * P, G + 3 * P)]),
}


def test_the_issue_41_case_answers_the_tuple_of_one_grid_point_unflagged():
    plan = tuple_reply(ISSUE_41, G + 70 * MS)
    assert picked(plan, ISSUE_41) == {"left": G + 15_200_000, "right": G + 15_700_000}
    assert plan.body["skew_ns"] == 500_000 and "grid_mismatch" not in plan.body


# right captured G 35 ms late: 15 ms before left's G + P, 35 ms after left's G
LATE_RIGHT = [(G + 35 * MS, G), (G + 3 * P, G + 3 * P)]


def test_a_tuple_of_one_grid_point_is_preferred_to_a_less_skewed_one_of_two():
    snaps = {"left": lockstep([(G, G), (G + P, G + P), (G + 2 * P, G + 2 * P)]), "right": lockstep(LATE_RIGHT)}
    least = select_joint({c: s.timeline for c, s in snaps.items()}, G + 40 * MS, P)
    assert least.t == {"left": G + P, "right": G + 35 * MS}  # without grid points: 15 ms, of two points
    plan = tuple_reply(snaps, G + 40 * MS)
    assert picked(plan, snaps) == {"left": G, "right": G + 35 * MS}
    assert plan.body["skew_ns"] == 35 * MS and "grid_mismatch" not in plan.body


def test_with_no_tuple_of_one_grid_point_stored_the_reply_names_each_cameras_point():
    snaps = {"left": lockstep([(G + P, G + P), (G + 2 * P, G + 2 * P)]), "right": lockstep(LATE_RIGHT)}  # left lost G
    plan = tuple_reply(snaps, G + 40 * MS)
    assert picked(plan, snaps) == {"left": G + P, "right": G + 35 * MS}
    assert plan.body["grid_mismatch"] == {"left": G + P, "right": G}
    assert plan.body["skew_ns"] == 15 * MS


def test_independent_tuples_are_flagged_not_changed():
    snaps = {"left": lockstep([(G, G), (G + P, G + P)]), "right": lockstep(LATE_RIGHT)}
    plan = tuple_reply(snaps, G + 40 * MS, sync=INDEPENDENT)
    assert picked(plan, snaps) == {"left": G + P, "right": G + 35 * MS}  # each one's nearest
    assert plan.body["grid_mismatch"] == {"left": G + P, "right": G}


def test_free_running_frames_are_never_flagged():
    free = {"left": lockstep([(G, G), (G + P, G + P)], CAPTURE_FREE), "right": lockstep(LATE_RIGHT, CAPTURE_FREE)}
    plan = tuple_reply(free, G + 40 * MS)
    assert picked(plan, free) == {"left": G + P, "right": G + 35 * MS}  # least skew: time alone decides
    assert "grid_mismatch" not in plan.body


def test_a_free_camera_beside_lockstep_ones_is_chosen_by_time_around_their_grid_point():
    snaps = {
        "left": lockstep([(G, G), (G + P, G + P), (G + 2 * P, G + 2 * P)]),
        "right": lockstep(LATE_RIGHT),
        "free": lockstep([(G + 30 * MS, 0), (G + 80 * MS, 0)], CAPTURE_FREE),
    }
    plan = tuple_reply(snaps, G + 40 * MS)
    assert picked(plan, snaps) == {"left": G, "right": G + 35 * MS, "free": G + 30 * MS}
    assert "grid_mismatch" not in plan.body


def test_among_tuples_of_one_point_the_least_skewed_wins_then_the_closest_then_the_newest():
    def grid_of(points):
        return lambda cam, i: points[cam][i]

    timelines = {"a": ring([0, 100, 200]), "b": ring([30, 130, 230])}
    points = {"a": [1, 2, 3], "b": [1, 2, 3]}
    off = select_joint(timelines, 116, 100, 0)  # (100, 130) is nearest; on grid: kept as it is
    assert on_grid(off, timelines, 116, 100, 0, grid_of(points), JOINT) is off
    shifted = {"a": [1, 2, 3], "b": [0, 1, 2]}  # b's frames are of the points before a's
    sel = on_grid(off, timelines, 116, 100, 0, grid_of(shifted), JOINT)
    # of one point: (0, 130) of 1 and (100, 230) of 2, both 130 apart; 2's is nearer t* (114 to 116)
    assert sel.t == {"a": 100, "b": 230} and sel.grid_mismatch is None
    assert sel.least_skew_ns == 130  # the least over the tuples of one point
    assert on_grid(off, timelines, 30, 100, 0, grid_of(shifted), JOINT).t == {"a": 0, "b": 130}
    assert on_grid(off, timelines, 115, 100, 0, grid_of(shifted), JOINT).t == {"a": 100, "b": 230}  # a tie: the newer
    # a tuple of one point less skewed by no more than the tolerance counts as least skewed
    skewed = {"a": ring([0, 100, 200]), "b": ring([30, 120, 230])}  # point 1: 120 apart, point 2: 130
    least = select_joint(skewed, 116, 120, 0)
    assert least.t == {"a": 100, "b": 120}  # 20 apart, of points 2 and 1
    for tolerance, expected in ((9, {"a": 0, "b": 120}), (10, {"a": 100, "b": 230})):
        sel = on_grid(least, skewed, 116, 120, tolerance, grid_of(shifted), JOINT)
        assert sel.t == expected and sel.least_skew_ns == 120


def test_max_skew_is_judged_on_the_tuple_of_one_grid_point():
    snaps = {"left": lockstep([(G, G), (G + P, G + P), (G + 2 * P, G + 2 * P)]), "right": lockstep(LATE_RIGHT)}
    assert picked(tuple_reply(snaps, G + 40 * MS, max_skew_ms=35.0), snaps) == {"left": G, "right": G + 35 * MS}
    with pytest.raises(Reject) as raised:
        tuple_reply(snaps, G + 40 * MS, max_skew_ms=20.0)
    assert raised.value.code == Code.SKEW_EXCEEDED
    assert "a skew of 35.000 ms" in raised.value.message


# ---- the client's side --------------------------------------------------------------------------


def reply_header(grid_mismatch=None) -> dict:
    frames = [
        {"camera": c, "frame_id": 7, "t_capture": t, "t_stored": t + 2, "generation": 1, "capture": "lockstep",
         "t_target": g}
        for c, t, g in (("left", G + P, G + P), ("right", G + 35 * MS, G))
    ]  # fmt: skip
    header = {"op": "tuple", "t_request": G + 40 * MS, "skew_ns": 15 * MS, "sync": "joint", "frames": frames}
    return {**header, "grid_mismatch": grid_mismatch} if grid_mismatch else header


def test_a_frame_tuple_says_its_grid_mismatch_in_the_callers_clock():
    images = [np.zeros((2, 2), np.uint8)] * 2
    assert tuple_of(reply_header(), images).grid_mismatch == {}
    header = in_caller_clock(reply_header({"left": G + P, "right": G}), ClockEstimate(offset_ns=1_000))
    got = tuple_of(header, images)
    assert got.grid_mismatch == {"left": G + P - 1_000, "right": G - 1_000}
    assert got.grid_mismatch == {c: got[c].t_target for c in got}  # the frames' own points
    assert "grid_mismatch={'left'" in repr(got)


def test_each_tuple_of_a_sequence_says_its_own_grid_mismatch_in_the_callers_clock():
    """A sequence of two tuples, the second of two points (decisions._sequence: one entry per tuple)."""
    one = reply_header()["frames"]
    header = {
        "op": "sequence",
        "t_request": G,
        "targets": [G, G + P],
        "frames": [{**f, "t_target": G + P} for f in one] + one,
        "groups": [[0, 1], [2, 3]],
        "grid_mismatch": [None, {"left": G + P, "right": G}],
    }
    first, second = sequence_of(in_caller_clock(header, ClockEstimate(offset_ns=1_000)), [np.zeros((2, 2))] * 4)
    assert first.grid_mismatch == {} and first.t_request == G - 1_000
    assert second.grid_mismatch == {"left": G + P - 1_000, "right": G - 1_000}
    assert second.grid_mismatch == {c: second[c].t_target for c in second}


# ---- the edges of the search for a tuple of one point (each kills a mutant of make mutation) ----


def test_a_flagged_tuple_keeps_the_least_skew_its_search_saw():
    timelines = {"a": ring([0, 100]), "b": ring([30, 130])}
    points = {"a": [1, 2], "b": [0, 3]}  # no point has a frame of both
    chosen = select_joint(timelines, 116, 100, 0)
    flagged = on_grid(Selection(chosen.index, chosen.t, 5), timelines, 116, 100, 0, lambda c, i: points[c][i], JOINT)
    assert flagged.grid_mismatch == {"a": 2, "b": 3} and flagged.least_skew_ns == 5


def test_a_frame_of_the_point_farther_than_a_period_from_every_candidate_is_not_matched():
    # right captured G 200 ms late (a stalled worker) and nothing since; left's frame of G is 200 ms
    # before every centre (t*, and the nearest frames): not a candidate, so the tuple is flagged
    left = [(G + k * P, G + k * P) for k in range(5)]
    snaps = {"left": lockstep(left), "right": lockstep([(G + 200 * MS, G)])}
    plan = tuple_reply(snaps, G + 200 * MS)
    assert picked(plan, snaps) == {"left": G + 4 * P, "right": G + 200 * MS}
    assert plan.body["grid_mismatch"] == {"left": G + 4 * P, "right": G}


def test_a_later_point_of_every_camera_is_found_past_an_earlier_point_one_camera_lacks():
    # left lost G; right captured G 35 ms and G + P 30 ms late: (G + P, G + P) is the tuple of one point
    snaps = {
        "left": lockstep([(G - P, G - P), (G + P, G + P), (G + 2 * P, G + 2 * P)]),
        "right": lockstep([(G + 35 * MS, G), (G + 80 * MS, G + P)]),
    }
    plan = tuple_reply(snaps, G + 40 * MS)
    assert plan.picks == [("left", 1), ("right", 1)] and "grid_mismatch" not in plan.body
    assert plan.body["skew_ns"] == 30 * MS


def test_the_least_skewed_tuple_of_one_point_wins_when_an_earlier_point_is_more_skewed():
    points = {"a": [1, 2, 3], "b": [0, 1, 2]}
    skewed = {"a": ring([0, 100, 200]), "b": ring([40, 140, 220])}  # point 1: 140 apart; point 2: 120
    least = select_joint(skewed, 116, 120, 0)
    sel = on_grid(least, skewed, 116, 120, 0, lambda c, i: points[c][i], JOINT)
    assert sel.t == {"a": 100, "b": 220} and sel.least_skew_ns == 120


def test_a_free_cameras_frame_beside_a_point_is_a_candidate_only_within_a_period_of_a_centre():
    # the tuple of point G (left's, right's captured 35 ms late); free's frame 5 ms after G is within
    # a period of left's frame, so (G, G + 35, G + 5) with 35 ms of skew beats (.., G + 62) with 62
    snaps = {
        "left": lockstep([(G - P, G - P), (G, G), (G + P, G + P), (G + 2 * P, G + 2 * P)]),
        "right": lockstep(LATE_RIGHT),
        "free": lockstep([(G + 5 * MS, 0), (G + 62 * MS, 0)], CAPTURE_FREE),
    }
    plan = tuple_reply(snaps, G + 40 * MS, tolerance_ms=3.0)
    assert plan.picks == [("left", 1), ("right", 0), ("free", 0)] and "grid_mismatch" not in plan.body


def test_a_free_camera_beside_a_point_gets_its_frame_by_the_requests_t_star_and_tolerance():
    # with the tuple of point G (left's G, right's G + 35): free's frame 10 ms before G makes 45 ms
    # of skew, its frame 47 ms after G 47 ms; within the 3 ms tolerance the one nearer t* wins
    snaps = {
        "left": lockstep([(G - P, G - P), (G, G), (G + P, G + P), (G + 2 * P, G + 2 * P)]),
        "right": lockstep(LATE_RIGHT),
        "free": lockstep([(G - 10 * MS, 0), (G + 47 * MS, 0)], CAPTURE_FREE),
    }
    plan = tuple_reply(snaps, G + 40 * MS, tolerance_ms=3.0)
    assert plan.picks == [("left", 1), ("right", 0), ("free", 1)] and plan.body["skew_ns"] == 47 * MS
    strict = tuple_reply(snaps, G + 40 * MS, tolerance_ms=1.0)  # 2 ms more skew is too much
    assert strict.picks == [("left", 1), ("right", 0), ("free", 0)] and strict.body["skew_ns"] == 45 * MS


# ---- a sequence of tuples: each held to one grid point, or flagged at its place (decisions._sequence) ----

# b captures on the grid; a captures 35 ms late and lost point G + 2P: by time alone, each of b's
# frames is nearest a's frame of the point before (15 ms), its own point's frame is 35 ms away.
B_ON_TIME = lockstep([(G + k * P, G + k * P) for k in range(5)])
A_LATE = lockstep([(G + k * P + 35 * MS, G + k * P) for k in (0, 1, 3, 4)])


def sequence_reply(snaps, t_star, sync=JOINT, **fields) -> Plan:
    names = list(snaps)
    request = request_of("sequence", id=None, cameras=names, at=t_star, **fields)
    p = Pending(None, request, names, t_star + 500 * MS, t_star)
    states = {c: CameraState(s.newest, P, 2 * MS, s.newest_stored) for c, s in snaps.items()}
    decision = decide(p, t_star + 900 * MS, snaps, states, Context({c: P for c in names}, NONE, sync, 1.0, None, 500))
    assert isinstance(decision, Plan)
    return decision


def tuples_picked(plan: Plan, snaps) -> list[dict[str, int]]:
    """Each tuple's frames, by capture time."""
    assert plan.groups is not None
    return [{c: snaps[c].timeline.at(i) for c, i in group} for group in plan.groups]


def ms_after_g(tuples) -> list[dict[str, int]]:
    return [{c: (t - G) // MS for c, t in frames.items()} for frames in tuples]


SNAPS = {"b": B_ON_TIME, "a": A_LATE}  # b first: b's frames are the reference times
LOST = {"b": G + 2 * P, "a": G + P}  # b's frame of the point a lost, beside a's nearest, of the point before


@pytest.mark.parametrize(
    "t_star,fields",
    [
        (G, {"kind": "range", "start": G + P, "end": G + 4 * P}),
        (G + 4 * P, {"kind": "consecutive", "count": 4, "direction": "before"}),
    ],
)
def test_each_tuple_of_a_sequence_pairs_a_reference_frame_with_the_frames_of_its_grid_point(t_star, fields):
    plan = sequence_reply(SNAPS, t_star, **fields)
    assert ms_after_g(tuples_picked(plan, SNAPS)) == [
        {"b": 50, "a": 85},
        {"b": 100, "a": 85},
        {"b": 150, "a": 185},
        {"b": 200, "a": 235},
    ]
    assert plan.body["grid_mismatch"] == [None, LOST, None, None]  # one entry per tuple, at its place


def test_a_tuple_of_an_interval_sequence_is_the_tuple_of_one_grid_point_nearest_its_target():
    """Target G + 2P (100 ms): b's frame of it has no partner of its point, so the tuple is G + P's."""
    plan = sequence_reply(SNAPS, G + P, kind="interval", count=4, interval_ms=50)
    assert ms_after_g(tuples_picked(plan, SNAPS)) == [
        {"b": 50, "a": 85},
        {"b": 50, "a": 85},
        {"b": 150, "a": 185},
        {"b": 200, "a": 235},
    ]
    assert plan.body["targets"] == [G + k * P for k in range(1, 5)] and "grid_mismatch" not in plan.body


@pytest.mark.parametrize(
    "t_star,fields",
    [
        (G, {"kind": "range", "start": G + P, "end": G + 4 * P}),
        (G + P, {"kind": "interval", "count": 4, "interval_ms": 50}),
    ],
)
def test_independent_tuples_of_a_sequence_are_each_flagged_not_changed(t_star, fields):
    plan = sequence_reply(SNAPS, t_star, INDEPENDENT, **fields)
    assert ms_after_g(tuples_picked(plan, SNAPS)) == [
        {"b": 50, "a": 35},
        {"b": 100, "a": 85},
        {"b": 150, "a": 185},
        {"b": 200, "a": 185},
    ]
    before = [{"b": G + k * P, "a": G + (k - 1) * P} for k in range(1, 5)]
    assert plan.body["grid_mismatch"] == [before[0], before[1], None, before[3]]


def test_a_sequence_of_one_camera_is_never_flagged():
    plan = sequence_reply({"a": A_LATE}, G + P, kind="interval", count=3, interval_ms=50)
    assert ms_after_g(tuples_picked(plan, {"a": A_LATE})) == [{"a": 35}, {"a": 85}, {"a": 185}]
    assert "grid_mismatch" not in plan.body
