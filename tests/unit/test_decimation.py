import random

import pytest

from fxis_shm.core.decimation import Decimator, every_frame

RATES = [1, 7, 10, 12.5, 30]
CAMERA_FPS = [15, 20, 25, 30, 100]


def camera_times(fps: float, seconds: float, jitter_ns: int = 300_000, seed: int = 0) -> list[int]:
    """Capture times of a free-running camera with timing jitter."""
    rng = random.Random(seed)
    period = 1e9 / fps
    return [int(5_000_000 + k * period + rng.uniform(-jitter_ns, jitter_ns)) for k in range(int(seconds * fps))]


def sent(rate, times, period):
    d = Decimator(rate)
    return [t for t in times if d.offer(t, period)]


@pytest.mark.parametrize("fps", CAMERA_FPS)
@pytest.mark.parametrize("rate", RATES)
def test_the_long_run_rate_is_the_one_asked_for(rate, fps):
    period = int(1e9 / fps)
    times = camera_times(fps, 12.0)
    out = sent(rate, times, period)
    expected_rate = min(rate, fps)
    for start_s in range(0, 9, 3):  # every window of 3 s holds the rate within one frame
        lo, hi = times[0] + start_s * 10**9, times[0] + (start_s + 3) * 10**9
        count = sum(lo <= t < hi for t in out)
        assert abs(count - 3 * expected_rate) <= 1, (start_s, count)


@pytest.mark.parametrize("fps", CAMERA_FPS)
@pytest.mark.parametrize("rate", [r for r in RATES])
def test_each_frame_sent_is_the_nearest_to_its_schedule_time(rate, fps):
    period = int(1e9 / fps)
    times = camera_times(fps, 6.0, seed=1)
    out = sent(rate, times, period)
    if rate >= fps:
        assert out == times  # every frame, none twice
        return
    interval = 1e9 / rate
    for k, t in enumerate(out):
        ideal = out[0] + k * interval
        assert abs(t - ideal) <= period / 2 + 2 * 300_000, (k, (t - ideal) / 1e6)  # both jitter


def test_the_rate_the_old_rule_got_wrong():
    """10 Hz from 25 fps: 10 frames a second, not every second frame (12.5)."""
    times = camera_times(25, 10.0, jitter_ns=0)
    assert len(sent(10, times, 40_000_000)) == 100


def test_a_dropped_frame_moves_its_schedule_time_to_the_next_frame():
    times = [k * 10_000_000 for k in range(40) if k not in (10, 11)]  # 100 fps, two frames lost
    out = sent(10, times, 10_000_000)
    # Frames come one at a time: at 90 ms the 100 ms frame is still expected, so the schedule
    # time 100 ms goes to the first frame that came after the gap; then back on the schedule.
    assert out[:4] == [0, 120_000_000, 200_000_000, 300_000_000]


def test_no_rate_sends_everything_and_bad_rates_are_refused():
    assert sent(None, [1, 2, 3], 1) == [1, 2, 3]
    for bad in (0, -1, float("inf"), float("nan")):
        with pytest.raises(ValueError, match="positive"):
            Decimator(bad)


def test_every_frame_says_when_the_camera_is_slower_than_asked():
    assert every_frame(30, int(1e9 / 25)) and every_frame(25, 40_000_000)
    assert not every_frame(10, 40_000_000)


def test_irregular_frames_keep_the_rate():
    """Tuples complete irregularly: 15 a second on average, 20 to 93 ms apart. 12.5 Hz asked is 12.5 Hz got."""
    steps = [40_000_000, 93_333_333, 20_000_000, 113_333_333]  # mean 66.7 ms
    times, t = [], 0
    for k in range(600):
        times.append(t)
        t += steps[k % len(steps)]
    chosen = sent(12.5, times, 66_666_667)
    seconds = (times[-1] - times[0]) / 1e9
    assert abs(len(chosen) - 12.5 * seconds) <= 1


def test_a_stall_is_not_followed_by_a_burst():
    period = 66_666_667
    times = [k * period for k in range(300) if not 75 <= k < 150]  # 5 s without frames
    resumed = [t for t in sent(10, times, period) if t >= 150 * period]
    seconds = (times[-1] - 150 * period) / 1e9
    assert abs(len(resumed) - 10 * seconds) <= 1  # 10 Hz again at once: the 5 s missed are not caught up
