"""The synchronization layer on a real service: no spikes, no needless waits."""

import pytest

from fxis_shm import ServiceError, SkewExceeded, read_stamp

from ..conftest import wait_until
from .conftest import SMALL

pytestmark = pytest.mark.integration

PERIOD = 50_000_000  # 20 fps
PHASE = 1_000_000  # cam1 1 ms behind cam0, like the paper's cameras


@pytest.fixture(scope="module")
def paper_cameras():
    import os

    from fxis_shm.service.launch import ServiceProcess

    svc = ServiceProcess(
        ["--camera", f"cam0=synthetic:{SMALL}", "--camera", f"cam1=synthetic:phase_ms=1,{SMALL}"],
        stderr=open(os.devnull, "w"),
    ).start()
    with svc.client() as client:  # full rings (20 slots) that have wrapped around
        wait_until(
            lambda: all(c["frames_stored"] > 25 for c in client.status()["cameras"].values()), what="the rings to fill"
        )
    yield svc
    svc.stop()


def halfway_times(client, count):
    """t* values halfway between the frames of the two cameras, all in the past
    (the frames around them are stored) and spread over the ring."""
    newest = client.latest()
    t0 = newest["cam0"].t_capture
    return [t0 - k * PERIOD - PERIOD // 2 + PHASE // 2 for k in range(1, count + 1)]


def test_requests_halfway_between_frames_never_spike(paper_cameras):
    with paper_cameras.client() as client:
        times = halfway_times(client, 12)
        independent = [client.tuple(at=t, sync="independent").skew_ns for t in times]
        joint = [client.tuple(at=t).skew_ns for t in times]
    # the paper's per-camera search spikes on every one of these ...
    assert min(independent) > PERIOD - 2 * PHASE
    # ... the joint selection never does: the smallest skew the cameras allow is 1 ms
    assert max(joint) <= PHASE + 2_000_000


def test_t_star_in_the_past_returns_without_waiting(paper_cameras):
    with paper_cameras.client() as client:
        t_star = client.latest()["cam0"].t_capture - 3 * PERIOD
        for sync in ("joint", "independent"):
            frames = client.tuple(at=t_star, sync=sync)
            timing = frames.timing
            assert all(c["waited"] == timing["received"] for c in timing["cameras"].values())
            assert abs(frames["cam0"].t_capture - t_star) <= PERIOD // 2


def test_t_star_in_the_future_waits_for_the_frames_around_it(paper_cameras):
    with paper_cameras.client() as client:
        t_star = client.time() + 4 * PERIOD
        frames = client.tuple(at=t_star)
        for frame in frames.values():
            assert abs(frame.t_capture - t_star) <= PERIOD // 2 + PHASE
            assert frame.t_stored >= t_star - PERIOD // 2
            assert read_stamp(frame.image) == frame.frame_id
        assert frames.timing["waited"] >= t_star - PERIOD


def test_wait_next_always_waits_for_a_new_frame(paper_cameras):
    """The paper's policy: every request waits until each camera stored a frame after it arrived."""
    with paper_cameras.client() as client:
        before = {name: f.frame_id for name, f in client.latest().items()}
        frames = client.tuple(wait="next", sync="independent")
        after = client.latest()
    timing = frames.timing
    for name, cam in timing["cameras"].items():
        assert cam["waited"] > timing["received"]
        assert after[name].frame_id > before[name]


def test_max_skew_is_enforced_with_the_best_skew_in_the_message(paper_cameras):
    with paper_cameras.client() as client:
        with pytest.raises(SkewExceeded, match=r"skew of 1\.\d+ ms"):
            client.tuple(max_skew_ms=0.5)
        assert client.tuple(max_skew_ms=1.5).skew_ns <= 1_500_000


def test_t_star_older_than_the_rings_is_refused(paper_cameras):
    with paper_cameras.client() as client:
        with pytest.raises(ServiceError, match="older than the oldest frame") as err:
            client.tuple(at=client.time() - 10_000_000_000)
    assert err.value.code == "OUT_OF_RANGE"
