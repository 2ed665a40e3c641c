"""The pure core's decisions, exactly: sequence arithmetic (fxis_shm.core.sequences), ``decide``
(fxis_shm.core.decisions) and the boundaries of the wait policy, the selection and the timeline
that the other unit tests leave open. Each test here kills mutants `make mutation` found
surviving (docs/mutation.md); each states the behaviour it pins."""

from __future__ import annotations

import numpy as np
import pytest

from fxis_shm.core import sequences
from fxis_shm.core.decisions import (
    Context,
    Plan,
    Reject,
    Wait,
    check_history,
    check_not_empty,
    check_size,
    decide,
    sequence_spec,
)
from fxis_shm.core.engine import Pending
from fxis_shm.core.selection import radius_for, select, select_joint, tolerance_for
from fxis_shm.core.sequences import SequenceSpec
from fxis_shm.core.snapshot import SLOT, Snapshot
from fxis_shm.core.timesearch import Timeline
from fxis_shm.core.waitpolicy import (
    AUTO,
    NEXT,
    NONE,
    CameraState,
    give_up_time,
    waiting_for,
    waiting_for_selection,
    with_predictions,
)
from fxis_shm.errors import Code
from fxis_shm.wire.protocol import request_of

from .timeline_helpers import MS, ring

P = 50 * MS  # frame period
DELAY = 2 * MS  # capture to storage


# ---- helpers: snapshots, camera states, requests ------------------------------------------------


def snap(times, stored=None) -> Snapshot:
    """A ring holding frames captured at ``times`` (oldest first), stored ``stored`` (default: a
    DELAY after capture)."""
    stored = [t + DELAY for t in times] if stored is None else stored
    meta = np.zeros(max(1, len(times)), dtype=SLOT)
    for w, (t, s) in enumerate(zip(times, stored)):
        meta[w] = (2 * w + 2, w, t, s, t, 1, 0, 0)
    return Snapshot.of_table(Timeline(list(times), 0, len(times)), 0, meta)


def state(s: Snapshot, period: int = P) -> CameraState:
    n = len(s.timeline)
    return CameraState(
        newest=s.newest, period_ns=period, delay_ns=DELAY, newest_stored=s.frame_meta(n - 1).t_stored if n else None
    )


def ctx(periods, wait=AUTO, sync="joint", tolerance_ms=1.0, max_skew_ms=None, max_frames=500) -> Context:
    return Context(dict(periods), wait, sync, tolerance_ms, max_skew_ms, max_frames)


def pending(op, cameras, t_star, t_received=None, **fields) -> Pending:
    if op in ("image", "sequence") and "camera" not in fields and "cameras" not in fields:
        fields["camera" if op == "image" else "cameras"] = cameras[0] if op == "image" else list(cameras)
    return Pending(
        None, request_of(op, id=None, **fields), list(cameras), t_star if t_received is None else t_received, t_star
    )


def decide_on(p, now, snaps, context, periods=None):
    periods = periods or {c: P for c in snaps}
    return decide(p, now, snaps, {c: state(s, periods[c]) for c, s in snaps.items()}, context)


def times_of(plan: Plan, snaps) -> dict:
    return {c: snaps[c].timeline.at(i) for c, i in plan.picks}


# ---- sequences: what a sequence needs and names --------------------------------------------------


@pytest.mark.parametrize(
    "direction, count, latest, earliest",
    [
        ("before", 4, 0, -3),
        ("after", 4, 3, 0),
        ("around", 4, 2, -1),  # 4 frames centred on t*: 1 before, t*'s, 2 after
        ("around", 5, 2, -2),
    ],
)
def test_a_consecutive_sequence_needs_frames_from_and_to_whole_periods_of_t_star(direction, count, latest, earliest):
    spec = SequenceSpec(sequences.CONSECUTIVE, 1000 * MS, count=count, direction=direction)
    assert sequences.latest_needed(spec, P) == 1000 * MS + latest * P
    assert sequences.earliest_needed(spec, P) == 1000 * MS + earliest * P


@pytest.mark.parametrize("interval_ms, latest_ms, earliest_ms", [(30, 1090, 1000), (-30, 1000, 910)])
def test_an_interval_sequence_needs_its_first_to_last_target(interval_ms, latest_ms, earliest_ms):
    spec = SequenceSpec(sequences.INTERVAL, 1000 * MS, count=4, interval_ns=interval_ms * MS)
    assert sequences.latest_needed(spec, P) == latest_ms * MS
    assert sequences.earliest_needed(spec, P) == earliest_ms * MS
    assert sequences.target_times(spec) == [(1000 + i * interval_ms) * MS for i in range(4)]


def test_a_range_needs_its_start_to_its_end():
    spec = SequenceSpec(sequences.RANGE, 0, start=200 * MS, end=450 * MS)
    assert (sequences.earliest_needed(spec, P), sequences.latest_needed(spec, P)) == (200 * MS, 450 * MS)


TEN = [k * 10 for k in range(10)]  # frames at 0, 10, ..., 90


@pytest.mark.parametrize("start", [0, 4])  # stored from the vector's start, and wrapped around its end
@pytest.mark.parametrize(
    "direction, t_star, count, indices",
    [
        ("before", 55, 3, [3, 4, 5]),
        ("before", 50, 3, [3, 4, 5]),  # a frame exactly at t* is "at or before" it
        ("before", 25, 3, [0, 1, 2]),  # reaching back to the oldest frame exactly
        ("after", 55, 3, [6, 7, 8]),
        ("after", 50, 3, [5, 6, 7]),  # a frame exactly at t* is "at or after" it
        ("after", 75, 2, [8, 9]),  # reaching the newest frame exactly
        ("around", 52, 3, [4, 5, 6]),
        ("around", 52, 4, [4, 5, 6, 7]),
        ("around", 52, 5, [3, 4, 5, 6, 7]),
        ("around", 52, 7, [2, 3, 4, 5, 6, 7, 8]),
    ],
)
def test_consecutive_reference_frames(start, direction, t_star, count, indices):
    spec = SequenceSpec(sequences.CONSECUTIVE, t_star, count=count, direction=direction)
    assert sequences.reference_indices(spec, ring(TEN, 12, start)) == indices


def test_range_reference_frames_are_those_captured_within_it():
    assert sequences.reference_indices(SequenceSpec(sequences.RANGE, 0, start=20, end=50), ring(TEN)) == [2, 3, 4, 5]
    assert sequences.reference_indices(SequenceSpec(sequences.RANGE, 0, start=21, end=29), ring(TEN)) == []


@pytest.mark.parametrize(
    "direction, t_star, count, error, message",
    [
        ("before", 15, 3, sequences.NotHeld, "only 2 frame(s) at or before the first needed one are held"),
        ("before", -5, 2, sequences.NotHeld, "only 0 frame(s) at or before the first needed one are held"),
        ("around", 12, 5, sequences.NotHeld, "only 4 frame(s) at or before the first needed one are held"),
        ("after", 85, 3, sequences.NotYet, "only 1 of 3 frames exist yet"),
        ("around", 80, 5, sequences.NotYet, "only 4 of 5 frames exist yet"),
    ],
)
def test_consecutive_frames_not_held_or_not_yet_there_say_how_many_are(direction, t_star, count, error, message):
    spec = SequenceSpec(sequences.CONSECUTIVE, t_star, count=count, direction=direction)
    with pytest.raises(error) as raised:
        sequences.reference_indices(spec, ring(TEN))
    assert str(raised.value) == message


def test_an_interval_sequence_has_target_times_not_reference_frames():
    with pytest.raises(ValueError, match="^interval sequences have target times, not reference frames$"):
        sequences.reference_indices(SequenceSpec(sequences.INTERVAL, 0, count=2, interval_ns=10), ring(TEN))


def test_a_sequence_request_becomes_its_spec():
    raw = request_of("sequence", id=None, camera="a", kind="interval", count=3, interval_ms=2.5)
    assert sequence_spec(raw, 7) == SequenceSpec(sequences.INTERVAL, 7, 3, "before", 2_500_000, 0, 0)
    raw = request_of("sequence", id=None, camera="a", kind="range", start=11, end=22)
    assert sequence_spec(raw, 7) == SequenceSpec(sequences.RANGE, 7, 1, "before", 0, 11, 22)
    raw = request_of("sequence", id=None, camera="a", kind="consecutive", count=2, direction="after")
    assert sequence_spec(raw, 7) == SequenceSpec(sequences.CONSECUTIVE, 7, 2, "after", 0, 0, 0)


# ---- decide: sequences ------------------------------------------------------------------------------


def two_cameras(a_times, b_times):
    return {"a": snap(a_times), "b": snap(b_times)}


def test_a_consecutive_sequence_of_tuples_is_led_by_the_first_camera():
    snaps = two_cameras([k * P for k in range(10)], [k * P + MS for k in range(10)])
    p = pending("sequence", ["a", "b"], 5 * P + 10 * MS, kind="consecutive", count=3, direction="before")
    plan = decide_on(p, 20 * P, snaps, ctx({"a": P, "b": P}))
    assert isinstance(plan, Plan)
    assert plan.body == {"op": "sequence", "t_request": 5 * P + 10 * MS, "targets": [3 * P, 4 * P, 5 * P]}
    assert plan.groups == [[("a", 3), ("b", 3)], [("a", 4), ("b", 4)], [("a", 5), ("b", 5)]]
    assert plan.picks == [("a", 3), ("b", 3), ("a", 4), ("b", 4), ("a", 5), ("b", 5)]


def test_a_sequence_waits_for_the_other_cameras_frame_near_the_last_reference_time():
    # a's frames reach 9 P; b's only 6 P: the tuple at 7 P needs b's next frame
    snaps = two_cameras([k * P for k in range(10)], [k * P + MS for k in range(7)])
    p = pending("sequence", ["a", "b"], 4 * P + MS, kind="consecutive", count=3, direction="after")
    decision = decide_on(p, 6 * P + 10 * MS, snaps, ctx({"a": P, "b": P}))
    assert decision == Wait({"b": None}, "the frame of camera 'b' near the last reference time")
    # ... and not before: the same sequence of 2 needs b's frames up to 6 P only
    p = pending("sequence", ["a", "b"], 4 * P + MS, kind="consecutive", count=2, direction="after")
    assert isinstance(decide_on(p, 6 * P + 10 * MS, snaps, ctx({"a": P, "b": P})), Plan)


def test_an_empty_range_is_an_empty_sequence_for_several_cameras():
    snaps = two_cameras([k * P for k in range(10)], [k * P for k in range(10)])
    p = pending("sequence", ["a", "b"], 9 * P, kind="range", start=2 * P + 1, end=3 * P - 1)
    plan = decide_on(p, 10 * P, snaps, ctx({"a": P, "b": P}))
    assert isinstance(plan, Plan) and plan.picks == [] and plan.body["targets"] == []


def test_a_sequence_not_there_yet_waits_and_one_not_held_is_refused():
    snaps = {"a": snap([k * P for k in range(10)])}
    p = pending("sequence", ["a"], 8 * P, kind="consecutive", count=3, direction="after")
    decision = decide_on(p, 12 * P, snaps, ctx({"a": P}))  # past the wait for 10 P: frame 10 was dropped
    assert decision == Wait({"a": None}, "the frames of camera 'a' (only 2 of 3 frames exist yet)")
    p = pending("sequence", ["a"], 9 * P, kind="consecutive", count=12, direction="before")
    with pytest.raises(Reject) as raised:
        decide_on(p, 9 * P + MS, snaps, ctx({"a": P}))
    assert (raised.value.code, raised.value.message) == (
        Code.OUT_OF_RANGE,
        "camera 'a': only 10 frame(s) at or before the first needed one are held",
    )


def test_a_sequence_reaching_future_frames_waits_for_them():
    snaps = {"a": snap([k * P for k in range(10)])}
    p = pending("sequence", ["a"], 9 * P, kind="consecutive", count=3, direction="after")
    decision = decide_on(p, 9 * P + MS, snaps, ctx({"a": P}))
    assert isinstance(decision, Wait) and set(decision.until) == {"a"}
    assert decision.reason == "the frames awaited from ['a']"


def test_an_interval_sequence_chooses_a_tuple_per_target():
    snaps = two_cameras([k * P for k in range(10)], [k * P + 2 * MS for k in range(10)])
    p = pending("sequence", ["a", "b"], 2 * P, kind="interval", count=3, interval_ms=2 * P / MS)
    plan = decide_on(p, 10 * P, snaps, ctx({"a": P, "b": P}))
    assert plan.body["targets"] == [2 * P, 4 * P, 6 * P]
    assert plan.groups == [[("a", 2), ("b", 2)], [("a", 4), ("b", 4)], [("a", 6), ("b", 6)]]


@pytest.mark.parametrize("kind, fields", [("interval", {"count": 2, "interval_ms": 10.0}), ("range", {})])
def test_interval_and_range_sequences_older_than_a_ring_are_refused_naming_the_camera(kind, fields):
    # b's ring reaches back to 5 P only; the sequence starts at 2 P
    snaps = two_cameras([k * P for k in range(10)], [k * P for k in range(5, 10)])
    if kind == "range":
        fields = {"start": 2 * P, "end": 3 * P}
    p = pending("sequence", ["a", "b"], 2 * P, t_received=10 * P, kind=kind, **fields)
    with pytest.raises(Reject) as raised:
        decide_on(p, 10 * P, snaps, ctx({"a": P, "b": P}))
    assert raised.value.code == Code.OUT_OF_RANGE
    assert raised.value.message == (
        "asks for frames 150.0 ms older than the oldest frame of camera 'b'; its ring holds 5 frames, "
        "the oldest from 250.0 ms before the request"
    )


def test_interval_and_range_sequences_half_a_period_older_than_the_ring_are_answered():
    # b's ring starts at 5 P; the sequences reach back to 4.5 P: b's frame nearest is its oldest
    snaps = two_cameras([k * P for k in range(10)], [k * P for k in range(5, 10)])
    start = 5 * P - P // 2
    for fields in ({"kind": "interval", "count": 2, "interval_ms": 25.0}, {"kind": "range", "start": start}):
        fields.setdefault("end", 6 * P) if fields["kind"] == "range" else None
        p = pending("sequence", ["a", "b"], start, t_received=10 * P, **fields)
        assert isinstance(decide_on(p, 10 * P, snaps, ctx({"a": P, "b": P})), Plan)


def test_a_consecutive_sequence_is_checked_by_index_not_by_time():
    # b's ring starts at 5 P, a's sequence reaches 2 P: b's frames nearest to a's are still chosen
    snaps = two_cameras([k * P for k in range(10)], [k * P for k in range(5, 10)])
    p = pending("sequence", ["a", "b"], 3 * P, kind="consecutive", count=2, direction="before")
    plan = decide_on(p, 10 * P, snaps, ctx({"a": P, "b": P}))
    assert plan.groups == [[("a", 2), ("b", 0)], [("a", 3), ("b", 0)]]


@pytest.mark.parametrize("limit, refused", [(5, True), (6, False)])
def test_a_sequence_of_more_frames_than_the_limit_is_refused(limit, refused):
    snaps = two_cameras([k * P for k in range(10)], [k * P for k in range(10)])
    p = pending("sequence", ["a", "b"], 5 * P, kind="consecutive", count=3)
    context = ctx({"a": P, "b": P}, max_frames=limit)
    if not refused:
        assert len(decide_on(p, 10 * P, snaps, context).picks) == 6
        return
    with pytest.raises(Reject) as raised:
        decide_on(p, 10 * P, snaps, context)
    assert (raised.value.code, str(raised.value)) == (Code.TOO_LARGE, "the sequence names 6 frames; the limit is 5")


# ---- decide: latest, image, tuple -----------------------------------------------------------------


def test_latest_is_each_cameras_newest_frame():
    snaps = two_cameras([0, P, 2 * P], [MS, P + MS])
    plan = decide_on(pending("latest", ["a", "b"], 0), 3 * P, snaps, ctx({"a": P, "b": P}))
    assert plan == Plan({"op": "latest"}, [("a", 2), ("b", 1)])


def test_no_frame_yet_is_refused_naming_the_camera():
    with pytest.raises(Reject) as raised:
        check_not_empty({"a": snap([0]), "b": snap([])})
    assert (raised.value.code, raised.value.message) == (Code.NO_FRAMES, "camera(s) ['b'] have stored no frame yet")


# Two cameras whose least-skewed tuple, far from t*, has a skew of exactly 1 ms, while a tuple
# 1 ns more skewed lies next to t* (within the 1 ms tolerance: it is what joint chooses); an
# older, more skewed tuple (50, 51.5 ms) is outside the window around t*.
NEAR_T = 150 * MS
SKEWED = two_cameras([50 * MS, 100 * MS, 150 * MS], [51_500_000, 101 * MS, 151 * MS + 1])
LEAST = {"a": 100 * MS, "b": 101 * MS}
CLOSE = {"a": 150 * MS, "b": 151 * MS + 1}


def tuple_at(t_star, snaps, now=200 * MS, **settings) -> Plan:
    p = pending("tuple", ["a", "b"], t_star)
    return decide_on(p, now, snaps, ctx({"a": P, "b": P}, **settings))


def test_a_tuple_reply_says_its_skew_and_sync_mode():
    plan = tuple_at(NEAR_T, SKEWED, wait=NONE)
    assert times_of(plan, SKEWED) == CLOSE
    assert plan.body == {"op": "tuple", "t_request": NEAR_T, "skew_ns": 1 * MS + 1, "sync": "joint"}
    p = pending("tuple", ["a", "b"], NEAR_T)
    p.missing = ["c"]
    assert decide_on(p, 200 * MS, SKEWED, ctx({"a": P, "b": P}, wait=NONE)).body["missing"] == ["c"]


def test_the_sync_tolerance_is_the_requests():
    # with no tolerance the least-skewed tuple wins however far from t* it is
    assert times_of(tuple_at(NEAR_T, SKEWED, wait=NONE, tolerance_ms=0), SKEWED) == LEAST


def test_max_skew_takes_the_least_skewed_tuple_when_it_meets_the_limit_exactly():
    plan = tuple_at(NEAR_T, SKEWED, wait=NONE, max_skew_ms=1.0)
    assert times_of(plan, SKEWED) == LEAST and plan.body["skew_ns"] == 1 * MS


def test_max_skew_under_the_least_skew_is_refused_saying_the_best_there_was():
    with pytest.raises(Reject) as raised:
        tuple_at(NEAR_T, SKEWED, wait=NONE, max_skew_ms=0.5)
    assert raised.value.code == Code.SKEW_EXCEEDED
    assert raised.value.message == "the best tuple near t* has a skew of 1.000 ms, more than max_skew_ms=0.5"


def test_max_skew_above_the_skew_changes_nothing():
    assert times_of(tuple_at(NEAR_T, SKEWED, wait=NONE, max_skew_ms=2.0), SKEWED) == CLOSE


def test_a_tuple_as_skewed_as_max_skew_exactly_is_kept():
    snaps = two_cameras([100 * MS, 150 * MS], [101 * MS, 151_500_000])  # near t*: 1.5 ms
    plan = tuple_at(NEAR_T, snaps, wait=NONE, max_skew_ms=1.5)
    assert times_of(plan, snaps) == {"a": 150 * MS, "b": 151_500_000}


def test_the_refusal_rounds_the_best_skew_to_microseconds():
    snaps = two_cameras([100 * MS, 150 * MS], [102_000_501, 152_500_000])
    with pytest.raises(Reject, match=r"a skew of 2\.001 ms, more than max_skew_ms=1\.0$"):
        tuple_at(NEAR_T, snaps, wait=NONE, max_skew_ms=1.0)


def test_an_image_at_a_time_older_than_its_ring_is_refused_naming_the_camera():
    snaps = {"a": snap([k * P for k in range(4, 10)])}
    p = pending("image", ["a"], P, t_received=10 * P, at=P)
    with pytest.raises(Reject) as raised:
        decide_on(p, 10 * P, snaps, ctx({"a": P}))
    assert raised.value.code == Code.OUT_OF_RANGE and "camera 'a'" in raised.value.message


def test_waiting_for_next_frames_also_reaches_a_future_t_star():
    snaps = {"a": snap([k * P for k in range(10)])}
    newest = 9 * P
    # "next": a frame stored after the request arrived is there; t* is a period ahead of it
    p = pending("image", ["a"], newest + P, t_received=newest - MS)
    decision = decide_on(p, newest + 10 * MS, snaps, ctx({"a": P}, wait=NEXT))
    assert decision == Wait({"a": give_up_time(newest + P, state(snaps["a"]))}, "the frames awaited from ['a']")
    # a t* that is now (and a period after the newest frame) is answered with the newest frame
    p = pending("image", ["a"], newest + P, t_received=newest - MS)
    plan = decide_on(p, newest + P, snaps, ctx({"a": P}, wait=NEXT))
    assert plan.picks == [("a", 9)]


# ---- decide: auto waits, with the stored tuple nearer than the coming one -------------------------

# a runs at 50 ms, b at 48.5 ms: the coming tuple (150, 150.2) is 1.5 ms less skewed than the
# stored one (100, 101.7), which is nearer to t* = 124 ms. With a 1 ms tolerance the coming
# tuple is chosen over stored and predicted frames; the stored one is at most twice the
# tolerance more skewed, so it is answered at once (predictions carry no jitter).
B_PERIOD = 48_500_000
COMING = {"a": snap([50 * MS, 100 * MS]), "b": snap([53_200_000, 101_700_000])}
COMING_PERIODS = {"a": P, "b": B_PERIOD}


def test_auto_answers_with_the_stored_tuple_when_it_is_nearer_and_within_twice_the_tolerance():
    p = pending("tuple", ["a", "b"], 124 * MS)
    plan = decide_on(p, 124 * MS, COMING, ctx(COMING_PERIODS, tolerance_ms=1.0), COMING_PERIODS)
    assert isinstance(plan, Plan) and times_of(plan, COMING) == {"a": 100 * MS, "b": 101_700_000}


def test_auto_waits_for_the_less_skewed_coming_tuple_beyond_twice_the_tolerance():
    p = pending("tuple", ["a", "b"], 124 * MS)
    decision = decide_on(p, 124 * MS, COMING, ctx(COMING_PERIODS, tolerance_ms=0.7), COMING_PERIODS)
    assert isinstance(decision, Wait) and set(decision.until) == {"a", "b"}


# ---- decide: software triggers ---------------------------------------------------------------------

T = 1000 * MS  # the trigger


def triggered_image(frames, t_trigger=T):
    """An image of triggered camera a; frames: (t_capture, t_stored)."""
    snaps = {"a": snap([c for c, _ in frames], [s for _, s in frames])}
    p = pending("image", ["a"], t_trigger)
    p.triggered, p.t_trigger = frozenset({"a"}), t_trigger
    return decide_on(p, t_trigger + 200 * MS, snaps, ctx({"a": P}, wait=NONE))


@pytest.mark.parametrize(
    "frames, picked",
    [
        # the frame nearest to the trigger was stored before it: not this request's
        (
            [
                (T - 1 * MS, T - MS // 2),
                (T + 3 * MS, T + 4 * MS),
                (T + 53 * MS, T + 54 * MS),
                (T + 103 * MS, T + 104 * MS),
            ],
            1,
        ),
        ([(T - 60 * MS, T - 59 * MS), (T - 2 * MS, T - 1 * MS), (T + 3 * MS, T + 4 * MS)], 2),
        ([(T + 1 * MS, T + 2 * MS), (T + 51 * MS, T + 52 * MS)], 0),  # every frame after the trigger
        ([(T - 5 * MS, T - 4 * MS), (T - 1 * MS, T), (T + 2 * MS, T + 3 * MS)], 1),  # stored at the trigger: after it
    ],
)
def test_a_triggered_camera_answers_with_a_frame_stored_after_the_trigger(frames, picked):
    assert triggered_image(frames).picks == [("a", picked)]


def test_a_trigger_waits_for_its_frame_and_the_free_cameras_for_theirs():
    snaps = {"a": snap([T - 60 * MS, T + 3 * MS], [T - 59 * MS, T + 4 * MS]), "b": snap([T - 3 * P, T - 2 * P])}
    p = pending("tuple", ["a", "b"], T)
    p.triggered, p.t_trigger = frozenset({"a"}), T
    decision = decide_on(p, T + 5 * MS, snaps, ctx({"a": P, "b": P}))
    assert decision == Wait({"b": give_up_time(T, state(snaps["b"]))}, "the frames awaited from ['b']")


# ---- checks -----------------------------------------------------------------------------------------


def test_history_reaches_back_half_a_period_before_the_oldest_frame():
    s = snap([10 * P, 11 * P, 12 * P])
    check_history("a", s, 10 * P - 25 * MS, 13 * P, P)  # exactly half a period before the oldest: answered
    check_history("a", s, 10 * P - 12_500_000, 13 * P, 25_000_001)  # half an odd period, rounded down
    for t_star, period in ((10 * P - 25 * MS - 1, P), (10 * P - 12_500_001, 25_000_001)):
        with pytest.raises(Reject) as more:
            check_history("a", s, t_star, 13 * P, period)
        assert more.value.code == Code.OUT_OF_RANGE
    with pytest.raises(Reject) as raised:
        check_history("a", s, 10 * P - 150_050_001, 10 * P + 250_050_001, P)
    assert raised.value.code == Code.OUT_OF_RANGE
    assert raised.value.message == (
        "asks for frames 150.1 ms older than the oldest frame of camera 'a'; its ring holds 3 frames, "
        "the oldest from 250.1 ms before the request"
    )


def test_a_sequence_of_exactly_the_limit_is_allowed():
    check_size(6, 6)
    with pytest.raises(Reject, match="^the sequence names 7 frames; the limit is 6$"):
        check_size(7, 6)


def test_a_reject_is_an_exception_with_its_message():
    assert str(Reject(Code.BUSY, "try again")) == "try again"


# ---- the wait policy's edges --------------------------------------------------------------------


def test_give_up_time_is_whole_nanoseconds_for_an_odd_period():
    cam = CameraState(newest=0, period_ns=3, delay_ns=10)
    assert give_up_time(100, cam) == 100 + 1 + 3 + 10


def test_auto_waits_from_half_an_odd_period_on_and_for_a_one_ns_period():
    assert waiting_for(AUTO, 1, 0, {"a": CameraState(newest=0, period_ns=3)}) == {"a": 1 + 1 + 3}
    assert waiting_for(AUTO, 0, 0, {"a": CameraState(newest=0, period_ns=1)}) == {"a": 0 + 1}


def test_next_counts_a_frame_stored_at_the_arrival():
    assert waiting_for(NEXT, 0, 0, {"a": CameraState(newest=0, period_ns=P, newest_stored=0)}) == {}
    assert waiting_for(NONE, 0, 0, {"a": CameraState(newest=None, period_ns=P)}) == {}


def test_no_predictions_without_a_newest_frame_or_a_period():
    tl = ring([0, 10])
    assert with_predictions(tl, CameraState(newest=None, period_ns=P), 0, 10**9) == (tl, [])
    assert with_predictions(tl, CameraState(newest=10, period_ns=0), 0, 10**9) == (tl, [])
    extended, predicted = with_predictions(tl, CameraState(newest=10, period_ns=1), 0, 13)
    assert predicted == [11, 12, 13] and [extended.at(i) for i in range(len(extended))] == [0, 10, 11, 12, 13]


def coming(b_newest: int, b_period: int, choose_tolerance: int, **kwargs):
    """``waiting_for_selection`` over COMING's shape: a at 50 ms, b at ``b_newest`` + ``b_period``."""
    tls = {"a": ring([50 * MS, 100 * MS]), "b": ring([b_newest - b_period, b_newest])}
    states = {
        "a": CameraState(newest=100 * MS, period_ns=P, delay_ns=DELAY),
        "b": CameraState(newest=b_newest, period_ns=b_period, delay_ns=DELAY),
    }
    return waiting_for_selection(
        124 * MS, 124 * MS, tls, states, lambda t: select_joint(t, 124 * MS, P, choose_tolerance), P, **kwargs
    )


@pytest.mark.parametrize("tolerance, waits", [(750_000, False), (600_000, True)])
def test_a_stored_tuple_up_to_twice_the_tolerance_more_skewed_is_answered(tolerance, waits):
    # stored skew 1.7 ms, coming 0.2 ms: 1.5 ms apart, twice 0.75 ms exactly
    assert bool(coming(101_700_000, B_PERIOD, 1 * MS, tolerance_ns=tolerance)) == waits


def test_the_default_tolerance_of_the_wait_is_none():
    # stored 2 ns more skewed than coming: answered only with a tolerance of at least 1 ns
    assert coming(101_700_000, 46_600_002, 0) != {}
    assert coming(101_700_000, 46_600_002, 0, tolerance_ns=1) == {}


# ---- the selection's edges ------------------------------------------------------------------------


def test_the_closest_of_a_cameras_frames_inside_the_window_is_taken():
    # c's frame at 3 closes the window [a 0, b 1, b 2, c 3]: b has two frames in it, 2 is nearer
    tls = {"a": ring([0]), "b": ring([1, 2]), "c": ring([3])}
    assert select_joint(tls, 3, 10, 0).index == {"a": 0, "b": 1, "c": 0}


def test_the_default_sync_tolerance_is_1_ms():
    tls = {"a": ring([100 * MS, 150 * MS]), "b": ring([101 * MS, 151 * MS + 1])}
    assert select_joint(tls, NEAR_T, P).t == CLOSE
    assert select("joint", tls, NEAR_T, P).t == CLOSE
    tls = {"a": ring([100 * MS, 150 * MS]), "b": ring([101 * MS, 152 * MS + 1])}  # 1 ms + 1 ns more
    assert select_joint(tls, NEAR_T, P).t == LEAST and select("joint", tls, NEAR_T, P).t == LEAST


def test_a_joint_selection_keeps_the_least_skew_it_saw():
    tls = {"a": ring([100 * MS, 150 * MS]), "b": ring([101 * MS, 151 * MS + 1])}
    sel = select_joint(tls, NEAR_T, P, 1 * MS)
    assert (sel.skew_ns, sel.least_skew_ns, sel.best_skew_ns) == (1 * MS + 1, 1 * MS, 1 * MS)
    assert select("joint", tls, NEAR_T, P, 0).t == LEAST  # the tolerance given is the one used


def test_radius_and_tolerance_from_the_periods():
    assert radius_for({}) == 0 and radius_for({"a": P, "b": 40 * MS}) == P
    assert tolerance_for({}, 1.0) == 1 * MS
    assert tolerance_for({"a": 0, "b": 40 * MS}, 5.0) == 5 * MS  # an unknown period caps nothing
    assert tolerance_for({"a": 40 * MS}, 20.0) == 10 * MS  # a quarter of the shortest period
    assert tolerance_for({"a": 1}, 1.0) == 0
    capped = tolerance_for({"a": 50_000_001}, 20.0)
    assert capped == 12_500_000 and type(capped) is int


# ---- the timeline's edges -------------------------------------------------------------------------


def test_a_timeline_knows_whether_its_frames_wrap():
    assert Timeline([1, 2, 3], 0, 3).contiguous is True
    assert Timeline([1, 2, 3, 4], 1, 3).contiguous is True  # up to the vector's end exactly
    assert Timeline([1, 2, 3, 4], 2, 3).contiguous is False


def test_timeline_errors_say_what_is_wrong():
    with pytest.raises(ValueError, match=r"^bad timeline: start=0 count=4 n=3$"):
        Timeline([1, 2, 3], 0, 4)
    with pytest.raises(ValueError, match="^no frames to search$"):
        Timeline([], 0, 0).nearest(5)


def test_each_reference_frame_of_a_sequence_is_paired_with_the_others_frames_nearest_it_alone():
    # b's frame 8 ms before a's frame at 5 P is its partner, though b's frame 3 ms before a's next
    # frame (6 P) is nearer that one: each tuple is led by its own reference frame
    snaps = two_cameras([k * P for k in range(10)], [5 * P - 8 * MS, 6 * P - 3 * MS])
    p = pending("sequence", ["a", "b"], 5 * P, kind="consecutive", count=1, direction="after")
    plan = decide_on(p, 20 * P, snaps, ctx({"a": P, "b": P}))
    assert plan.groups == [[("a", 5), ("b", 0)]]
