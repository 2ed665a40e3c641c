"""One client over several services: their cameras as one set (issue 11, item 6).
Here the services share a host; tests/integration/test_hosts.py runs them on emulated hosts."""

import os
import signal

import pytest

from fxis_shm import CameraDown, Client, UnknownCamera, read_stamp
from fxis_shm.client.multiclient import MultiClient
from fxis_shm.errors import ConfigError

from ..conftest import wait_until
from .conftest import SMALL, child_pids

pytestmark = pytest.mark.integration


TWO_SERVICES = (  # the two_services fixtures (conftest.py) start these
    ["--camera", f"left=synthetic:fps=50,{SMALL}"],
    ["--camera", f"right=synthetic:fps=50,phase_ms=7,{SMALL}", "--camera", f"top=synthetic:fps=25,phase_ms=3,{SMALL}"],
)


def _least_skew_near(times: dict[str, list[int]], t_star: int, radius: int) -> int:
    """The least skew of any tuple of frames within ``radius`` of t* (brute force)."""
    near = {c: [t for t in ts if abs(t - t_star) <= radius] for c, ts in times.items()}
    best = None

    def walk(cams, chosen):
        nonlocal best
        if not cams:
            skew = max(chosen) - min(chosen)
            best = skew if best is None else min(best, skew)
            return
        for t in near[cams[0]]:
            walk(cams[1:], chosen + [t])

    walk(list(near), [])
    return best


def test_a_tuple_across_services_is_the_least_skewed_one(two_services):
    a, b = two_services
    with Client([a.endpoint, b.endpoint]) as client:
        assert isinstance(client, MultiClient)
        assert set(client.cameras) == {"left", "right", "top"}
        wait_until(
            lambda: all(
                len(client.clients[i].frame_times()["cameras"][c]["frames"]) > 10 for i, c in ((0, "left"), (1, "top"))
            ),
            what="frames in every ring",
        )
        for back_ms in (30, 55, 80, 105, 130):
            t_star = client.clock() - back_ms * 1_000_000
            tup = client.tuple(at=t_star)
            assert set(tup) == {"left", "right", "top"}
            for frame in tup.values():
                assert read_stamp(frame.image) == frame.frame_id
            times = {}
            for sub in client.clients:
                for cam, info in sub.frame_times()["cameras"].items():
                    times[cam] = [row[1] for row in info["frames"]]
            least = _least_skew_near(times, t_star, 40_000_000)
            skew = max(f.t_capture for f in tup.values()) - min(f.t_capture for f in tup.values())
            assert skew <= least + 2_000_000, (back_ms, skew, least)


def test_single_frames_latest_and_sequences_across_services(two_services):
    a, b = two_services
    with MultiClient([a.endpoint, b.endpoint]) as client:
        wait_until(lambda: client.clients[1].frame_times(["top"])["cameras"]["top"]["frames"], what="a frame")
        frame = client.image("top")
        assert frame.camera == "top" and read_stamp(frame.image) == frame.frame_id
        latest = client.latest(["left", "top"])
        assert set(latest) == {"left", "top"}
        ahead = client.tuple(["left", "right"], at=client.clock() + 60_000_000)  # waits for frames to come
        assert all(f.t_stored > ahead.t_request - 40_000_000 for f in ahead.values())
        seq = client.sequence("consecutive", cameras=["left", "right"], count=3)
        assert len(seq) == 3 and all(set(t) == {"left", "right"} for t in seq)


def test_a_camera_name_in_two_services_is_refused_naming_both(start_service):
    a = start_service("--camera", f"cam=synthetic:fps=20,{SMALL}")
    b = start_service("--camera", f"cam=synthetic:fps=20,{SMALL}")
    with pytest.raises(ConfigError, match="'cam' is served by both") as err:
        MultiClient([a.endpoint, b.endpoint])
    assert a.endpoint in str(err.value) and b.endpoint in str(err.value)


def test_a_service_that_stops_gives_camera_down_or_is_left_out(two_services_to_stop):
    a, b = two_services_to_stop
    with MultiClient([a.endpoint, b.endpoint], timeout=2.0) as client:  # a busy machine may hold a service up
        wait_until(lambda: client.latest(), what="frames")
        with pytest.raises(UnknownCamera):
            client.tuple(["left", "nope"])
        (coordinator,) = child_pids(b, "coordinator")
        os.kill(coordinator, signal.SIGSTOP)  # the service hangs: nobody answers
        try:
            with pytest.raises(CameraDown, match=b.endpoint.replace(".", r"\.")):
                client.tuple()
            partial = client.tuple(partial=True)
            assert set(partial) == {"left"} and sorted(partial.missing) == ["right", "top"]
        finally:
            os.kill(coordinator, signal.SIGCONT)
        assert set(wait_until(lambda: _whole(client), what="the service back")) == {"left", "right", "top"}


def _whole(client):
    try:
        return client.tuple()
    except CameraDown:
        return None
