"""The restart limit counts the crashes of a recent window (fxis_shm.core.restarts), in virtual
time: a list of crash times and a clock value, no process and no waiting."""

import pytest

from fxis_shm.core.restarts import gives_up, recent_crashes
from fxis_shm.errors import ConfigError
from fxis_shm.service.config import build_config

WEEK = 7 * 86_400.0


def crash_loop(times, limit=5, window=600.0):
    """The decision after each crash at ``times``, feeding the supervisor's pruned history along."""
    history, decisions = [], []
    for now in times:
        history = recent_crashes([*history, now], now, window)
        decisions.append(gives_up(history, now, limit, window))
    return decisions


def test_a_camera_that_crashes_once_a_week_is_never_given_up_on():
    assert crash_loop([k * WEEK for k in range(200)]) == [False] * 200


def test_the_crash_after_the_limit_within_the_window_leaves_it_down():
    assert crash_loop([0.0, 10.0, 20.0, 30.0, 40.0, 50.0]) == [False] * 5 + [True]


def test_crashes_spread_wider_than_the_window_are_restarted_for_ever():
    # six crashes in every 10 min + 1 s: the oldest has always left the window
    assert crash_loop([k * 601.0 / 5 for k in range(100)]) == [False] * 100


def test_a_crash_exactly_a_window_ago_no_longer_counts():
    assert recent_crashes([0.0, 0.5, 600.0], 600.0, 600.0) == [0.5, 600.0]
    assert not gives_up([0.0, 600.0], 600.0, 1, 600.0)
    assert gives_up([0.5, 600.0], 600.0, 1, 600.0)


@pytest.mark.parametrize("limit", [0, 1, 5])
def test_limit_n_allows_n_restarts_in_a_window(limit):
    decisions = crash_loop([float(k) for k in range(limit + 1)], limit=limit)
    assert decisions == [False] * limit + [True]


def test_limit_one_after_a_quiet_spell_restarts_again():
    # issue 42's case: --restart-limit 1, a crash, 40 s, another: a 30 s window forgot the first
    assert crash_loop([0.0, 40.0], limit=1, window=30.0) == [False, False]
    assert crash_loop([0.0, 40.0], limit=1, window=600.0) == [False, True]


def test_the_window_is_ten_minutes_unless_the_config_or_the_flag_says_otherwise():
    assert build_config().restart_window_s == 600.0
    assert build_config({"restart_window_s": 30}).restart_window_s == 30.0
    assert build_config({"restart_window_s": 30}, {"restart_window_s": 5.5}).restart_window_s == 5.5


@pytest.mark.parametrize("bad", [0, -1, float("nan"), float("inf"), "soon", True])
def test_a_window_that_is_no_positive_number_is_refused(bad):
    with pytest.raises(ConfigError, match="restart_window_s must be"):
        build_config({"restart_window_s": bad})
