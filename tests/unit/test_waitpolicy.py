"""When a request waits for frames not stored yet (fxis_shm.waitpolicy)."""
from __future__ import annotations

import pytest

from fxis_shm.waitpolicy import AUTO, NEXT, NONE, CameraState, give_up_time, waiting_for
from .timeline_helpers import MS

PERIOD = 50 * MS
NEWEST = 1000 * MS  # capture time of the newest stored frame


def camera(newest=NEWEST, period_ns=PERIOD, count=10, baseline=10, delay_ns=0) -> CameraState:
    return CameraState(count=count, baseline=baseline, newest=newest, period_ns=period_ns,
                       delay_ns=delay_ns)


def waits(mode, t_star, now, **cameras):
    return waiting_for(mode, t_star, now, cameras)


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
    cam = camera(newest=None, count=0, baseline=0)
    assert waits(AUTO, NEWEST, NEWEST, cam=cam) == {"cam": None}
    assert waits(AUTO, NEWEST - 10 * PERIOD, NEWEST + 10**12, cam=cam) == {"cam": None}
    assert waits(AUTO, NEWEST, NEWEST, cam=camera(newest=None, period_ns=0)) == {"cam": None}


def test_auto_does_not_wait_when_the_frame_period_is_unknown():
    assert waits(AUTO, NEWEST + 10 * PERIOD, NEWEST, cam=camera(period_ns=0)) == {}


def test_auto_waits_only_for_the_cameras_that_are_behind():
    t_star = NEWEST + PERIOD
    result = waits(
        AUTO, t_star, NEWEST,
        current=camera(newest=t_star),  # already holds a frame at t*
        behind=camera(),
        empty=camera(newest=None),
        unknown_rate=camera(period_ns=0),
        slow=camera(period_ns=4 * PERIOD, delay_ns=MS),  # half a period (100 ms) covers t*
    )
    assert result == {"behind": t_star + PERIOD * 3 // 2, "empty": None}


# ---- next and none ----

@pytest.mark.parametrize(
    "count, baseline, waiting",
    [(10, 10, True), (9, 10, True), (11, 10, False), (0, 0, True), (1, 0, False)],
)
def test_next_waits_until_a_frame_arrives_after_the_request(count, baseline, waiting):
    cam = camera(count=count, baseline=baseline)
    for t_star in (NEWEST - 10 * PERIOD, NEWEST, NEWEST + 10 * PERIOD):  # t* does not matter
        assert waits(NEXT, t_star, NEWEST, cam=cam) == ({"cam": None} if waiting else {})


@pytest.mark.parametrize(
    "cam",
    [camera(), camera(newest=None, count=0, baseline=0), camera(count=3, baseline=5)],
)
def test_none_never_waits(cam):
    assert waits(NONE, NEWEST + 10 * PERIOD, NEWEST, cam=cam) == {}


@pytest.mark.parametrize("cameras", [{"cam": camera()}, {}])
def test_an_unknown_mode_is_an_error(cameras):
    with pytest.raises(ValueError, match="wait mode"):
        waiting_for("soon", NEWEST, NEWEST, cameras)
