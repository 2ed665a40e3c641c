"""The caller's clock, travel time and compressed frames, against real services on this host.

(A caller on another host, with a clock of its own, is tested in emulated hosts.)
"""

import time

import numpy as np
import pytest

from fxis_shm import Client, InvalidArgument, Subscriber, read_stamp
from fxis_shm.core.clockmap import ESTIMATED, SAME_CLOCK

from ..conftest import wait_until

MS = 1_000_000
MEDIUM = "width=320,height=240"


@pytest.fixture(scope="module")
def medium(request):
    """Two 320x240 cameras (large enough for the stamp to survive JPEG), one of them colour."""
    from .conftest import module_service

    yield from module_service(
        [
            "--camera",
            f"cam0=synthetic:fps=50,{MEDIUM}",
            "--camera",
            f"cam1=synthetic:fps=50,phase_ms=1,pixel_format=bgr8,{MEDIUM}",
        ]
    )


def _ready(client):
    wait_until(
        lambda: all(c.get("frames_stored", 0) > 5 for c in client.status()["cameras"].values()),
        what="frames in every ring",
    )


def test_on_the_services_own_clock_nothing_is_estimated(medium):
    with Client(medium.endpoint) as client:
        _ready(client)
        (clock,) = client.clocks.values()
        assert clock.method == SAME_CLOCK and clock.offset_ns == 0 and clock.uncertainty_ns == 0
        frame = client.image("cam0")
        assert frame.t_capture == frame.service_t_capture


@pytest.mark.parametrize("local", ["auto", "off"])
def test_a_caller_in_wall_clock_time_gives_and_gets_wall_clock_times(medium, local):
    with Client(medium.endpoint, clock=time.time_ns, local=local) as client:
        _ready(client)
        (clock,) = client.clocks.values()
        wall_minus_mono = time.time_ns() - time.monotonic_ns()
        assert clock.method == ESTIMATED
        assert abs(-clock.offset_ns - wall_minus_mono) < clock.uncertainty_ns + 2 * MS
        t_star = time.time_ns() - 100 * MS
        pair = client.tuple(at=t_star, wait="none")
        assert pair.t_request == pytest.approx(t_star, abs=1000)
        for frame in pair.values():
            assert abs(frame.t_capture - t_star) < 30 * MS  # 50 fps: the nearest frames
            assert abs(frame.t_capture - frame.service_t_capture - wall_minus_mono) < clock.uncertainty_ns + 2 * MS
        rows = client.sequence("range", camera="cam0", start=t_star - 50 * MS, end=t_star)
        assert rows and all(t_star - 50 * MS <= f.t_capture <= t_star for f in rows)


def test_a_call_without_at_means_the_moment_of_the_call(medium):
    with Client(medium.endpoint, local="off") as client:
        _ready(client)
        for _ in range(5):
            called = time.monotonic_ns()
            pair = client.tuple(wait="none")
            assert called <= pair.t_request <= pair.timing["received"]  # not the moment it arrived


@pytest.mark.parametrize("encoding, quality", [("jpeg", 90), ("jpeg", 75), ("png", None)])
def test_compressed_frames_keep_their_shape_and_stamp(medium, encoding, quality):
    with (
        Client(medium.endpoint, local="off") as raw,
        Client(medium.endpoint, local="off", encoding=encoding, quality=quality) as packed,
    ):
        _ready(raw)
        pair = packed.tuple(wait="none")
        same = {cam: raw.image(cam, at=frame.t_capture, wait="none") for cam, frame in pair.items()}
    for cam, frame in pair.items():
        assert frame.encoding == encoding and same[cam].encoding == "raw"
        assert frame.frame_id == same[cam].frame_id
        assert frame.image.shape == same[cam].image.shape and frame.image.dtype == np.uint8
        assert read_stamp(frame.image) == frame.frame_id
        error = np.abs(frame.image.astype(int) - same[cam].image.astype(int))
        if encoding == "png":
            assert error.max() == 0  # lossless
        else:  # the stated error of JPEG q>=75 on the synthetic pattern (colour: 4:2:0 chroma)
            assert error.mean() < (1.5 if frame.image.ndim == 2 else 6)


def test_a_frame_is_encoded_once_for_every_client_that_asks(medium):
    with (
        Client(medium.endpoint, local="off", encoding="jpeg") as a,
        Client(medium.endpoint, local="off", encoding="jpeg") as b,
    ):
        _ready(a)
        before = a.status()["encoded"]
        t_star = time.monotonic_ns() - 100 * MS  # in the past: every request picks the same frames
        a.tuple(at=t_star, wait="none")
        b.tuple(at=t_star, wait="none")
        b.tuple(at=t_star, wait="none", quality=60)  # another quality is another encoding
        after = a.status()["encoded"]
    assert after["encoded"] - before["encoded"] == 4  # 2 cameras x 2 qualities
    assert after["reused"] - before["reused"] == 2  # b's first tuple: a's encodings


def test_the_local_path_stays_raw(medium):
    with Client(medium.endpoint, local="require", encoding="jpeg") as client:
        _ready(client)
        frame = client.image("cam0")
    assert frame.path == "local" and frame.encoding == "raw"


def test_a_compressed_stream(medium):
    with Subscriber(medium.pub, timeout=5.0) as sub:
        sub.frames("cam1", encoding="jpeg", quality=80)
        message = sub.receive()
    (frame,) = message.frames
    assert frame.encoding == "jpeg" and frame.image.shape == (240, 320, 3)
    assert read_stamp(frame.image) == frame.frame_id


@pytest.mark.parametrize(
    "kwargs, says",
    [
        ({"encoding": "gif"}, "unknown encoding 'gif'"),
        ({"encoding": "jpeg", "quality": 0}, "quality must be an integer from 1 to 100"),
        ({"encoding": "jpeg", "quality": 101}, "quality must be an integer from 1 to 100"),
        ({"clock": 5}, "clock must be"),
        ({"clock": "sundial"}, "unknown clock 'sundial'"),
    ],
)
def test_bad_encodings_and_clocks_are_clear_errors(kwargs, says):
    with pytest.raises(InvalidArgument, match=says):
        Client("tcp://127.0.0.1:9", **kwargs)


def test_a_bad_encoding_on_the_wire_is_refused_and_the_service_goes_on(medium):
    import json

    import zmq

    sock = zmq.Context.instance().socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.connect(medium.endpoint)
    try:
        for fields, says in [({"encoding": "webp"}, "encoding"), ({"encoding": "jpeg", "quality": 500}, "quality")]:
            sock.send_multipart([b"", json.dumps({"v": 1, "op": "image", "camera": "cam0", **fields}).encode()])
            assert sock.poll(5000)
            header = json.loads(sock.recv_multipart()[-1])
            assert header["ok"] is False and header["error"]["code"] == "BAD_REQUEST"
            assert says in header["error"]["message"]
    finally:
        sock.close()
    with Client(medium.endpoint) as client:
        assert client.image("cam0").frame_id >= 0


def test_a_service_in_realtime_serves_callers_of_either_clock(start_service):
    svc = start_service("--clock", "realtime", "--camera", f"a=synthetic:fps=50,{MEDIUM}")
    with Client(svc.endpoint, clock="realtime") as wall, Client(svc.endpoint) as mono:
        _ready(wall)
        assert wall.status()["clock"] == "realtime"
        assert wall.clocks[svc.endpoint].method == SAME_CLOCK
        assert mono.clocks[svc.endpoint].method == ESTIMATED
        frame = wall.image("a", at=time.time_ns() - 50 * MS)
        assert abs(frame.t_capture - (time.time_ns() - 50 * MS)) < 100 * MS
        assert frame.path == "local"  # CLOCK_REALTIME is the same in every time namespace
        later = mono.image("a", wait="none")
        assert abs(later.t_capture - time.monotonic_ns()) < 200 * MS
        assert read_stamp(later.image) == later.frame_id
