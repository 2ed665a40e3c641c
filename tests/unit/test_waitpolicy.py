"""When a request waits for frames not stored yet (fxis_shm.core.waitpolicy)."""

from __future__ import annotations

import pytest

from fxis_shm.core.selection import select_independent, select_joint
from fxis_shm.core.timesearch import Timeline
from fxis_shm.core.waitpolicy import (
    AUTO,
    NEXT,
    NONE,
    CameraState,
    comes_by_itself,
    give_up_time,
    never_coming,
    waiting_for,
    waiting_for_selection,
    with_predictions,
)

from .timeline_helpers import MS

PERIOD = 50 * MS
NEWEST = 1000 * MS  # capture time of the newest stored frame


ARRIVAL = NEWEST + 10 * MS  # when the request arrived


def camera(newest=NEWEST, period_ns=PERIOD, delay_ns=0, stored=None, triggered=False) -> CameraState:
    if stored is None and newest is not None:
        stored = newest + delay_ns
    return CameraState(newest=newest, period_ns=period_ns, delay_ns=delay_ns, newest_stored=stored, triggered=triggered)


def waits(mode, t_star, now, **cameras):
    return waiting_for(mode, t_star, now, cameras, t_arrival=ARRIVAL)


# ---- auto ----


@pytest.mark.parametrize(
    "t_star, waiting",
    [
        (NEWEST - 10 * PERIOD, False),  # long past
        (NEWEST - 1, False),
        (NEWEST, False),  # the newest frame is exactly t*
        (NEWEST + PERIOD // 2 - 1, False),  # the newest frame stays the nearest
        (NEWEST + PERIOD // 2, True),  # halfway: the tie goes to the next (newer) frame
        (NEWEST + PERIOD // 2 + 1, True),  # the next frame will be nearer
        (NEWEST + PERIOD, True),
        (NEWEST + 10 * PERIOD, True),  # well into the future
    ],
)
def test_auto_waits_only_while_the_next_frame_could_be_nearer(t_star, waiting):
    now = NEWEST + 1  # just after the newest frame was stored
    result = waits(AUTO, t_star, now, cam=camera())
    assert result == ({"cam": t_star + PERIOD * 3 // 2} if waiting else {})


@pytest.mark.parametrize("delay_ns", [0, 3 * MS])
def test_auto_gives_up_once_the_next_frame_is_overdue(delay_ns):
    cam = camera(delay_ns=delay_ns)
    t_star = NEWEST + PERIOD  # the frame nearest t* is the next one
    give_up = t_star + PERIOD * 3 // 2 + delay_ns
    assert give_up_time(t_star, cam) == give_up
    assert waits(AUTO, t_star, give_up - 1, cam=cam) == {"cam": give_up}
    assert waits(AUTO, t_star, give_up, cam=cam) == {}
    assert waits(AUTO, t_star, give_up + PERIOD, cam=cam) == {}


def test_auto_never_waits_for_a_t_star_in_the_past_whatever_the_clock():
    for now in (NEWEST, NEWEST + PERIOD, NEWEST + 100 * PERIOD):
        assert waits(AUTO, NEWEST - PERIOD, now, cam=camera()) == {}


def test_auto_waits_until_the_deadline_for_a_camera_that_has_stored_nothing():
    cam = camera(newest=None)
    assert waits(AUTO, NEWEST, NEWEST, cam=cam) == {"cam": None}
    assert waits(AUTO, NEWEST - 10 * PERIOD, NEWEST + 10**12, cam=cam) == {"cam": None}
    assert waits(AUTO, NEWEST, NEWEST, cam=camera(newest=None, period_ns=0)) == {"cam": None}


def test_auto_does_not_wait_when_the_frame_period_is_unknown():
    assert waits(AUTO, NEWEST + 10 * PERIOD, NEWEST, cam=camera(period_ns=0)) == {}


def test_auto_waits_only_for_the_cameras_that_are_behind():
    t_star = NEWEST + PERIOD
    result = waits(
        AUTO,
        t_star,
        NEWEST,
        current=camera(newest=t_star),  # already holds a frame at t*
        behind=camera(),
        empty=camera(newest=None),
        unknown_rate=camera(period_ns=0),
        slow=camera(period_ns=4 * PERIOD, delay_ns=MS),  # half a period (100 ms) covers t*
    )
    assert result == {"behind": t_star + PERIOD * 3 // 2, "empty": None}


# ---- next and none ----


@pytest.mark.parametrize(
    "stored, waiting",
    [(ARRIVAL - 1, True), (None, True), (ARRIVAL, False), (ARRIVAL + 5 * MS, False)],
)
def test_next_waits_until_a_frame_is_stored_after_the_request_arrived(stored, waiting):
    cam = camera(newest=None if stored is None else NEWEST, stored=stored)
    for t_star in (NEWEST - 10 * PERIOD, NEWEST, NEWEST + 10 * PERIOD):  # t* does not matter
        assert waits(NEXT, t_star, ARRIVAL, cam=cam) == ({"cam": None} if waiting else {})


@pytest.mark.parametrize("cam", [camera(), camera(newest=None), camera(stored=ARRIVAL - 1)])
def test_none_never_waits(cam):
    assert waits(NONE, NEWEST + 10 * PERIOD, NEWEST, cam=cam) == {}


# ---- auto, deciding with the request's own selection ----


def flat(times):
    return Timeline(list(times), 0, len(times))


def grid(phase, up_to=NEWEST):
    """Frames every PERIOD at ``phase`` after a multiple of PERIOD, up to ``up_to``."""
    return [t for t in range(phase, up_to + 1, PERIOD)][-20:]


def test_predictions_extend_the_timeline_and_skip_overdue_frames():
    tl = flat(grid(0))
    cam = camera(newest=tl.at(len(tl) - 1))
    extended, predicted = with_predictions(tl, cam, now=NEWEST, up_to=NEWEST + 2 * PERIOD)
    assert predicted == [NEWEST + PERIOD, NEWEST + 2 * PERIOD]
    assert len(extended) == len(tl) + 2 and extended.at(len(tl)) == NEWEST + PERIOD
    _, late = with_predictions(tl, cam, now=NEWEST + 2 * PERIOD + 1, up_to=NEWEST + 2 * PERIOD)
    assert late == [NEWEST + 2 * PERIOD]  # the first predicted frame is overdue: dropped


@pytest.mark.parametrize(
    "offset, waiting", [(0, False), (PERIOD // 2 - 1, False), (PERIOD // 2, True), (PERIOD - 1, True)]
)
def test_one_camera_waits_as_the_per_camera_rule_says(offset, waiting):
    tl = flat(grid(0))
    cam = camera(newest=NEWEST)
    t_star = NEWEST + offset
    got = waiting_for_selection(
        t_star, NEWEST, {"c": tl}, {"c": cam}, lambda tls: select_independent(tls, t_star), PERIOD
    )
    assert ("c" in got) == waiting == bool(waits(AUTO, t_star, NEWEST, c=cam))


def joint_waits(phases, t_star, now, newest_up_to):
    timelines = {f"c{p}": flat(grid(p * MS, newest_up_to)) for p in phases}
    states = {n: camera(newest=tl.at(len(tl) - 1)) for n, tl in timelines.items()}
    choose = lambda tls: select_joint(tls, t_star, PERIOD)  # noqa: E731
    return waiting_for_selection(t_star, now, timelines, states, choose, PERIOD)


def test_joint_waits_for_a_partner_frame_the_per_camera_rule_ignores():
    # phases 0 and 20 ms; stored: c0 up to 1000, c20 up to 1020 ms; t* = 1044.
    # Least-skew tuples (20 ms): {1000, 1020} (44 ms from t*) or {1050, 1070} (26 ms):
    # the nearer one needs both next frames, though per camera c20's newest (1020)
    # is nearer to t* than its next (1070).
    got = joint_waits([0, 20], t_star=1044 * MS, now=1044 * MS, newest_up_to=1044 * MS)
    assert got == {"c0": 1050 * MS + PERIOD, "c20": 1070 * MS + PERIOD}
    assert waiting_for(AUTO, 1044 * MS, 1044 * MS, {"c20": camera(newest=1020 * MS)}) == {}


def test_joint_does_not_wait_for_frames_it_would_not_use():
    # phases 0, 10, 30 ms; stored up to 1031 ms; t* = 1026. The best tuple is
    # {1000, 1010, 1030}, all stored; per camera, c0 would wait for 1050.
    got = joint_waits([0, 10, 30], t_star=1026 * MS, now=1031 * MS, newest_up_to=1031 * MS)
    assert got == {}
    assert "c0" in waiting_for(AUTO, 1026 * MS, 1031 * MS, {"c0": camera(newest=1000 * MS)})


def test_no_wait_for_a_tuple_that_only_looks_less_skewed():
    # Seen in bench/latency/paper.py (phases 0, 10, 30 ms, jitter 0.3 ms), t* = 1026.4:
    # stored {c0 999.7, c10 1009.6, c30 1030.2} (skew 30.5, 26.7 from t*) against
    # predicted {c30 1030.2, c0 1049.7, c10 1059.6} (skew 29.4 without jitter, 33.2 from t*).
    t_star = 1026_400_000
    timelines = {"c0": flat([999_700_000]), "c10": flat([1_009_600_000]), "c30": flat([1_030_200_000])}
    states = {n: camera(newest=tl.at(0)) for n, tl in timelines.items()}
    choose = lambda tls: select_joint(tls, t_star, PERIOD, tolerance_ns=MS)  # noqa: E731
    now = 1031 * MS
    assert waiting_for_selection(t_star, now, timelines, states, choose, PERIOD, MS) == {}
    # without a tolerance, the strictly less skewed tuple is worth waiting for
    strict = lambda tls: select_joint(tls, t_star, PERIOD, tolerance_ns=0)  # noqa: E731
    assert set(waiting_for_selection(t_star, now, timelines, states, strict, PERIOD, 0)) == {"c0", "c10"}


def test_no_wait_for_a_tuple_only_as_much_nearer_as_the_jitter_allows():
    # As in bench/latency/wake.py (phases 0, 1 ms, jitter 0.3 ms, tolerance 2 ms): stored
    # {c0 1000.2, c1 1000.9}, t* about halfway to the predicted {c0 1050.2, c1 1050.9}, which is
    # 0.8 ms nearer (24.95 against 25.75 ms): within what the frames' jitter moves. It was waited
    # for; the real frames came farther than predicted and the stored tuple answered after all,
    # a period late (a 50.5 ms local wait in the demo).
    timelines = {"c0": flat([1_000_200_000]), "c1": flat([1_000_900_000])}
    states = {n: camera(newest=tl.at(0)) for n, tl in timelines.items()}
    now = 1002 * MS

    def wait_for(t_star, tolerance_ns=2 * MS):
        choose = lambda tls: select_joint(tls, t_star, PERIOD, tolerance_ns=tolerance_ns)  # noqa: E731
        return set(waiting_for_selection(t_star, now, timelines, states, choose, PERIOD, tolerance_ns))

    halfway = 1_025_950_000
    assert wait_for(halfway) == set()
    assert wait_for(halfway, tolerance_ns=0) == {"c0", "c1"}  # without a tolerance: strictly nearer waits
    assert wait_for(halfway + 2 * MS) == {"c0", "c1"}  # nearer by more than the tolerance: worth a period


def test_an_empty_camera_waits_until_the_deadline():
    states = {"a": camera(newest=None), "b": camera()}
    got = waiting_for_selection(
        NEWEST,
        NEWEST,
        {"a": flat([]), "b": flat(grid(0))},
        states,
        lambda tls: select_joint(tls, NEWEST, PERIOD),
        PERIOD,
    )
    assert got == {"a": None}


# ---- cameras that capture only on a trigger (issue 41) ----

TRIGGERS_APART = 1100 * MS  # the spacing of the triggers so far: the camera's measured "period"


def test_a_triggered_camera_gives_no_frame_by_itself_for_a_moment_past():
    trig, free = camera(period_ns=TRIGGERS_APART, triggered=True), camera()
    assert comes_by_itself(free, NEWEST, NEWEST + 1)
    assert comes_by_itself(trig, NEWEST + 2, NEWEST + 1)  # ahead: a capture at T may bring one
    assert not comes_by_itself(trig, NEWEST + 1, NEWEST + 1)
    empty = camera(newest=None, triggered=True)
    assert never_coming(NEWEST, NEWEST + 1, {"t": empty, "f": camera(newest=None), "s": trig}) == ["t"]
    assert never_coming(NEWEST + 2, NEWEST + 1, {"t": empty}) == []


def test_a_past_moment_on_triggered_cameras_waits_for_no_frame_the_trigger_spacing_predicts():
    # The case: triggers 1.1 s apart taught the cameras a "period"; their newest frames
    # are 0.9 s old and t* is 1 ms ago. A frame 1.1 s after the newest would be nearer t*, and
    # it was waited for until overdue, past the request's timeout: no trigger was coming.
    now = NEWEST + 900 * MS
    t_star = now - MS
    timelines = {"a": flat([NEWEST - TRIGGERS_APART, NEWEST]), "b": flat([NEWEST - TRIGGERS_APART, NEWEST + MS])}
    states = {n: camera(newest=tl.at(1), period_ns=TRIGGERS_APART, triggered=True) for n, tl in timelines.items()}
    choose = lambda tls: select_joint(tls, t_star, TRIGGERS_APART)  # noqa: E731
    assert waiting_for_selection(t_star, now, timelines, states, choose, TRIGGERS_APART) == {}
    assert waiting_for(AUTO, t_star, now, states) == {}
    free = {n: CameraState(s.newest, s.period_ns, s.delay_ns, s.newest_stored) for n, s in states.items()}
    assert set(waiting_for_selection(t_star, now, timelines, free, choose, TRIGGERS_APART)) == {"a", "b"}
    ahead = now + 500 * MS  # a moment ahead is still waited for as before
    choose_ahead = lambda tls: select_joint(tls, ahead, TRIGGERS_APART)  # noqa: E731
    assert set(waiting_for_selection(ahead, now, timelines, states, choose_ahead, TRIGGERS_APART)) == {"a", "b"}


@pytest.mark.parametrize("cameras", [{"cam": camera()}, {}])
def test_an_unknown_mode_is_an_error(cameras):
    with pytest.raises(ValueError, match="wait mode"):
        waiting_for("soon", NEWEST, NEWEST, cameras)


def test_a_triggered_camera_asked_for_a_past_moment_waits_for_nothing_beside_a_free_camera_that_does():
    # t* 29 ms after both newest frames, 1 ms ago: the free camera's next frame (21 ms from t*)
    # is coming and nearer, so it is waited for; the triggered one's never comes by itself. The
    # triggered camera is named first: the free one after it is still looked at.
    period = 50 * MS
    now = NEWEST + 30 * MS
    t_star = now - MS
    timelines = {"trig": flat([NEWEST - period, NEWEST]), "free": flat([NEWEST - period, NEWEST])}
    states = {
        "trig": camera(newest=NEWEST, period_ns=period, triggered=True),
        "free": camera(newest=NEWEST, period_ns=period),
    }
    assert set(waiting_for(AUTO, t_star, now, states)) == {"free"}
    choose = lambda tls: select_independent(tls, t_star)  # noqa: E731
    assert set(waiting_for_selection(t_star, now, timelines, states, choose, period)) == {"free"}
