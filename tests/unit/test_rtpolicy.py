"""The pure part of ``fxis run --realtime`` (fxis_shm.service.rtpolicy): the option, the
priority of each thread by its role, when memory may be locked, the status summary."""

import pytest

from fxis_shm.errors import ConfigError
from fxis_shm.service.config import build_config
from fxis_shm.service.rtpolicy import (
    DEFAULT_PRIORITY,
    NORMAL,
    PATH,
    TIMER,
    Realtime,
    camera_thread_role,
    coordinator_thread_role,
    memory_lock_allowed,
    parse_realtime,
    priority_of,
    sched_text,
    summary,
)


@pytest.mark.parametrize(
    "value, expected",
    [
        (None, None),
        (False, None),
        ("off", None),
        (True, Realtime(DEFAULT_PRIORITY)),
        ("on", Realtime(DEFAULT_PRIORITY)),
        (30, Realtime(30)),
        ("45", Realtime(45)),
        ("require", Realtime(DEFAULT_PRIORITY, require=True)),
        ("30,require", Realtime(30, require=True)),
    ],
)
def test_the_option_as_a_flag_or_a_config_value(value, expected):
    assert parse_realtime(value) == expected


@pytest.mark.parametrize("value", ["fast", "30,40", 50, 99, 1, 0, "-3"])
def test_a_bad_option_or_a_priority_at_the_kernels_is_refused_saying_why(value):
    with pytest.raises(ConfigError, match="realtime"):
        parse_realtime(value)


def test_the_config_takes_it_from_the_file_and_the_flag_wins():
    assert build_config({"realtime": 30}, {}).realtime == Realtime(30)
    assert build_config({"realtime": 30}, {"realtime": "require"}).realtime == Realtime(require=True)
    assert build_config({}, {}).realtime is None


def test_timers_run_above_the_rest_of_the_path_and_both_below_the_kernels_interrupt_threads():
    assert priority_of(TIMER, DEFAULT_PRIORITY) == 40 and priority_of(PATH, DEFAULT_PRIORITY) == 39
    assert priority_of(NORMAL, DEFAULT_PRIORITY) is None
    assert DEFAULT_PRIORITY < 50  # irq/N threads and watchdogd: `ps -eLo cls,rtprio,comm` on this machine


def test_a_camera_workers_threads_by_role():
    assert camera_thread_role("trigger-timer", "fxis camera", inline_hook=False) == TIMER
    for name in ("MainThread", "trigger", "commands"):
        assert camera_thread_role(name, "fxis camera", inline_hook=False) == PATH
    assert camera_thread_role(None, "ZMQbg/IO/0", inline_hook=False) == PATH  # the command socket's I/O
    assert camera_thread_role(None, "aravis-stream", inline_hook=False) == PATH  # a camera library's own
    assert camera_thread_role(None, "ZMQbg/Reaper", inline_hook=False) == NORMAL
    assert camera_thread_role("stop-on-signal", "fxis camera", inline_hook=False) == NORMAL
    assert camera_thread_role("QueueFeederThread", "fxis camera", inline_hook=False) == NORMAL  # a hook pool's
    # a hook run inline runs in the capture loop, for as long as it takes: not at FIFO
    assert camera_thread_role("MainThread", "fxis camera", inline_hook=True) == NORMAL
    assert camera_thread_role("trigger-timer", "fxis camera", inline_hook=True) == TIMER


def test_the_coordinators_loop_and_its_sockets_io_are_on_the_path_its_authenticator_is_not():
    assert coordinator_thread_role("MainThread", "fxis coord") == PATH
    assert coordinator_thread_role(None, "ZMQbg/IO/0") == PATH
    assert coordinator_thread_role("Thread-1", "fxis coord") == NORMAL
    assert coordinator_thread_role(None, "ZMQbg/Reaper") == NORMAL


def test_memory_is_locked_only_where_a_limit_cannot_make_later_mappings_fail():
    unlimited = -1
    assert memory_lock_allowed(unlimited, unlimited, can_lock=False)
    assert memory_lock_allowed(8 << 20, unlimited, can_lock=True)
    assert not memory_lock_allowed(8 << 20, unlimited, can_lock=False)


def test_a_processes_threads_summed_up_for_status():
    fifo = summary([(1, 40), (1, 39), (1, 39), (0, 0)])
    assert fifo == {"policy": "fifo", "priorities": [40, 39], "rt_threads": 3, "threads": 4}
    assert sched_text(fifo) == "fifo 40/39 (3 of 4 threads)"
    other = summary([(0, 0), (0, 0)])
    assert other == {"policy": "other", "priorities": [], "rt_threads": 0, "threads": 2}
    assert sched_text(other) == "other" and sched_text(None) == "-"
