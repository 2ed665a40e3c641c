"""Software-triggered cameras: a request triggers every camera of its tuple at once."""

import time

import pytest

from fxis_shm import read_stamp

from .conftest import SMALL

pytestmark = pytest.mark.integration


def test_a_tuple_request_triggers_every_camera_and_returns_those_frames(start_service):
    svc = start_service(
        "--camera", f"a=synthetic:trigger=software,{SMALL}", "--camera", f"b=synthetic:trigger=software,{SMALL}"
    )
    with svc.client() as client:
        assert client.status()["cameras"]["a"]["trigger"] == "software"
        previous = None
        for _ in range(5):
            frames = client.tuple()
            trigger = frames.t_request
            for frame in frames.values():
                assert frame.t_capture >= trigger  # captured because of this request
                assert read_stamp(frame.image) == frame.frame_id
            if previous is not None:
                assert all(frames[c].frame_id == previous[c].frame_id + 1 for c in frames)
            previous = frames
        # no trigger for a t* in the past: the stored frames answer it (t* at their own capture,
        # so that a loaded machine's late capture cannot make an earlier frame the nearer one)
        past = client.tuple(at=max(f.t_capture for f in previous.values()))
        assert {c: f.frame_id for c, f in past.items()} == {c: f.frame_id for c, f in previous.items()}


def test_a_free_running_camera_joins_a_triggered_one(start_service):
    svc = start_service(
        "--camera", f"trig=synthetic:trigger=software,{SMALL}", "--camera", f"free=synthetic:fps=50,{SMALL}"
    )
    with svc.client() as client:
        frames = client.tuple()
    assert frames["trig"].t_capture >= frames.t_request
    assert abs(frames["free"].t_capture - frames["trig"].t_capture) <= 10_000_000  # half a 50 fps period


def test_an_image_request_triggers_its_camera_and_returns_that_frame(start_service):
    svc = start_service(
        "--camera", f"a=synthetic:trigger=software,{SMALL}", "--camera", f"b=synthetic:trigger=software,{SMALL}"
    )
    with svc.client() as client:
        previous = None
        for n in range(1, 4):
            called = time.monotonic_ns()  # the service's clock too: same host, CLOCK_MONOTONIC
            frame = client.image("a")
            assert frame.camera == "a" and frame.t_capture >= called  # captured because of this request
            assert read_stamp(frame.image) == frame.frame_id
            if previous is not None:
                assert frame.frame_id == previous.frame_id + 1
            previous = frame
            cameras = client.status()["cameras"]
            # one frame per request, of the camera asked for only
            assert (cameras["a"]["frames_stored"], cameras["b"]["frames_stored"]) == (n, 0)
        # no trigger for a t* in the past: the stored frame answers it
        again = client.image("a", at=previous.t_capture)
        assert again.frame_id == previous.frame_id
        assert client.status()["cameras"]["a"]["frames_stored"] == 3
