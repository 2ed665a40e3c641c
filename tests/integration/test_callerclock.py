"""The caller's clock, travel time and compressed frames, against real services on this host.

(A caller on another host, with a clock of its own, is tested in emulated hosts.)
"""

import ctypes
import ctypes.util
import time

import numpy as np
import pytest

from fxis_shm import Client, InvalidArgument, Subscriber, read_stamp
from fxis_shm.core.clockmap import ESTIMATED, SAME_CLOCK

from ..conftest import wait_until
from .frozen import frozen, newest_of_all

pytestmark = pytest.mark.integration
MS = 1_000_000
MEDIUM = "width=320,height=240"


@pytest.fixture(scope="module")
def medium(request):
    """Two 320x240 cameras (large enough for the stamp to survive JPEG), one of them colour,
    whose rings hold 3 s: a test asks for t* 100 ms ago, and on a loaded machine its process
    may stall half a second before the ring is read (20 slots, 380 ms, then held too little)."""
    from .conftest import module_service

    yield from module_service(
        [
            "--slots",
            "150",
            "--camera",
            f"cam0=synthetic:fps=50,{MEDIUM}",
            "--camera",
            f"cam1=synthetic:fps=50,phase_ms=1,pixel_format=bgr8,{MEDIUM}",
        ]
    )


def _ready(client):
    """Frames enough in every ring for the oldest t* a test asks about, 150 ms before the newest
    frame: 16 frames at 50 fps span at least 300 ms. (More than 5 was too few: make test run 54
    asked 30 ms before the oldest of 8 frames, a service started 150 ms before.)"""
    wait_until(
        lambda: all(c.get("frames_stored", 0) >= 16 for c in client.status()["cameras"].values()),
        what="300 ms of frames in every ring",
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
        # 100 ms before the newest frame both cameras have stored (in the caller's clock), not
        # before now: a worker held up that long (a loaded machine) has not stored its frames of t*
        t_star = newest_of_all(client) - 100 * MS
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
    # qualities no other test of this service asks for: its earlier tests' encodings of the
    # same frames (at the default quality) must not count as this test's reuse
    with (
        Client(medium.endpoint, local="off", encoding="jpeg", quality=41) as a,
        Client(medium.endpoint, local="off", encoding="jpeg", quality=41) as b,
    ):
        _ready(a)
        # before the newest frame both cameras have stored (not before now: a worker held up on a
        # loaded machine may store a nearer one between the requests): every request picks the same frames
        t_star = newest_of_all(a, encoding="raw") - 100 * MS
        before = a.status()["encoded"]
        a.tuple(at=t_star, wait="none")
        b.tuple(at=t_star, wait="none")
        b.tuple(at=t_star, wait="none", quality=43)  # another quality is another encoding
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
        assert wall.status()["clock"] == "CLOCK_REALTIME"
        assert wall.clocks[svc.endpoint].method == SAME_CLOCK
        assert mono.clocks[svc.endpoint].method == ESTIMATED
        # a's worker stopped for the request and the read of its ring after it: a frame stored in
        # between (a worker held up, catching up) may be nearer to t*, or overwrite the one answered.
        # wait="none": a frame of t* the stopped worker had not stored yet is not coming.
        with frozen(wall, "a"):
            t_star = time.time_ns() - 50 * MS
            frame = wall.image("a", at=t_star, wait="none")
            ring = wall.frame_times(["a"])
        assert frame.path == "local"  # CLOCK_REALTIME is the same in every time namespace
        assert frame.t_capture == frame.service_t_capture  # the service's times are the caller's
        # the frame nearest to t* of those in the ring, in wall-clock time
        i_t = ring["columns"].index("t_capture")
        nearest = min((row[i_t] for row in ring["cameras"]["a"]["frames"]), key=lambda t: abs(t - t_star))
        assert frame.t_capture == nearest
        later = mono.image("a", wait="none")
        (estimate,) = mono.clocks.values()
        mono_minus_wall = time.monotonic_ns() - time.time_ns()
        # moved into the monotonic caller's clock by the estimated offset, right within its uncertainty
        assert abs(later.t_capture - later.service_t_capture - mono_minus_wall) < estimate.uncertainty_ns + 2 * MS
        assert later.t_capture <= time.monotonic_ns()
        assert read_stamp(later.image) == later.frame_id


class _Timex(ctypes.Structure):
    """Linux's struct timex (adjtimex(2)), for reading and setting the kernel's TAI offset."""

    _fields_ = [
        ("modes", ctypes.c_uint),
        ("offset", ctypes.c_long),
        ("freq", ctypes.c_long),
        ("maxerror", ctypes.c_long),
        ("esterror", ctypes.c_long),
        ("status", ctypes.c_int),
        ("constant", ctypes.c_long),
        ("precision", ctypes.c_long),
        ("tolerance", ctypes.c_long),
        ("time_sec", ctypes.c_long),
        ("time_usec", ctypes.c_long),
        ("tick", ctypes.c_long),
        ("ppsfreq", ctypes.c_long),
        ("jitter", ctypes.c_long),
        ("shift", ctypes.c_int),
        ("stabil", ctypes.c_long),
        ("jitcnt", ctypes.c_long),
        ("calcnt", ctypes.c_long),
        ("errcnt", ctypes.c_long),
        ("stbcnt", ctypes.c_long),
        ("tai", ctypes.c_int),
        ("padding", ctypes.c_int * 11),
    ]


_ADJ_TAI = 0x0080
TAI_OFFSET_S = 37  # TAI - UTC since 2017


def _tai_offset(set_to: int | None = None) -> int:
    libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
    timex = _Timex(modes=_ADJ_TAI, constant=set_to) if set_to is not None else _Timex()
    if libc.adjtimex(ctypes.byref(timex)) < 0:
        raise OSError(ctypes.get_errno(), "adjtimex")
    return timex.tai


@pytest.fixture
def tai_apart_from_realtime():
    """CLOCK_TAI 37 s ahead of CLOCK_REALTIME, as PTP or chrony keep it: without that offset
    (a host nothing sets it on) the two clocks read alike and a mix-up would go unseen. Sets the
    kernel's TAI offset for the test if it is 0 (needs root, as the suite does) and puts it back."""
    before = _tai_offset()
    if before == 0:
        try:
            _tai_offset(TAI_OFFSET_S)
        except OSError as exc:
            pytest.fail(f"cannot set the kernel's TAI offset (adjtimex ADJ_TAI needs root): {exc}", pytrace=False)
    try:
        apart = time.clock_gettime_ns(time.CLOCK_TAI) - time.time_ns()
        assert abs(apart - max(before, TAI_OFFSET_S) * 10**9) < 10 * MS, apart
        yield apart
    finally:
        if before == 0:
            _tai_offset(0)


def _nearest_in_ring(client, camera, t_star):
    """The capture time nearest to ``t_star`` among the frames in the camera's ring (service clock)."""
    ring = client.frame_times([camera])
    i_t = ring["columns"].index("t_capture")
    return min((row[i_t] for row in ring["cameras"][camera]["frames"]), key=lambda t: abs(t - t_star))


def test_a_caller_in_tai_time_against_a_monotonic_service(medium, tai_apart_from_realtime):
    with Client(medium.endpoint, clock="tai") as client:
        _ready(client)
        (clock,) = client.clocks.values()
        tai_minus_mono = time.clock_gettime_ns(time.CLOCK_TAI) - time.monotonic_ns()
        assert clock.method == ESTIMATED
        assert abs(-clock.offset_ns - tai_minus_mono) < clock.uncertainty_ns + 2 * MS
        with frozen(client, "cam0"):  # no frame stored between the answer and the ring's frames read after it
            t_star = time.clock_gettime_ns(time.CLOCK_TAI) - 100 * MS
            frame = client.image("cam0", at=t_star, wait="none")
            nearest = _nearest_in_ring(client, "cam0", clock.to_service(t_star))
        # in TAI, right within the estimate's uncertainty; the frame nearest to t* in the service's clock
        assert abs(frame.t_capture - frame.service_t_capture - tai_minus_mono) < clock.uncertainty_ns + 2 * MS
        assert frame.service_t_capture == nearest
        assert frame.t_capture <= time.clock_gettime_ns(time.CLOCK_TAI)
        assert read_stamp(frame.image) == frame.frame_id


def test_a_service_and_a_caller_both_on_tai(start_service, tai_apart_from_realtime):
    svc = start_service("--clock", "tai", "--camera", f"a=synthetic:fps=50,{MEDIUM}")
    with Client(svc.endpoint, clock="tai") as client:
        _ready(client)
        assert client.status()["clock"] == "CLOCK_TAI"
        (clock,) = client.clocks.values()
        assert clock.method == SAME_CLOCK and clock.offset_ns == 0
        with frozen(client, "a"):  # no frame stored between the answer and the ring's frames read after it
            t_star = time.clock_gettime_ns(time.CLOCK_TAI) - 50 * MS
            frame = client.image("a", at=t_star, wait="none")
            nearest = _nearest_in_ring(client, "a", t_star)
        assert frame.path == "local"  # CLOCK_TAI is the same in every time namespace
        assert frame.t_capture == frame.service_t_capture == nearest
        now_tai = time.clock_gettime_ns(time.CLOCK_TAI)
        # TAI, not the wall clock it is 37 s ahead of: captured within the ring's 400 ms before now
        assert now_tai - 5 * 10**9 < frame.t_capture <= now_tai
        assert read_stamp(frame.image) == frame.frame_id


DRIFT_PPM = 200.0


def test_the_drift_of_a_caller_clock_that_runs_fast_is_estimated_from_the_exchanges(medium):
    """A caller whose clock runs 200 ppm fast (crystals differ by tens of ppm; a time namespace
    gives an offset only): after the estimator's span of exchanges (10 s) the client has fitted
    the drift, and its mapping still puts the caller's times where they are on the service."""

    def fast_clock() -> int:
        return int(time.monotonic_ns() * (1 + DRIFT_PPM * 1e-6))

    with Client(medium.endpoint, clock=fast_clock, local="off") as client:
        _ready(client)
        assert client.clocks[medium.endpoint].method == ESTIMATED
        estimate = wait_until(
            lambda: (e := client.clocks[medium.endpoint]).drift_ppm != 0 and e,
            timeout=60,
            interval=0.5,
            what="a drift fitted over the exchanges",
        )
        # service = caller / (1 + 200e-6): the service's clock runs 200 ppm slow against the caller's
        assert estimate.drift_ppm == pytest.approx(-DRIFT_PPM, abs=20), estimate
        assert estimate.samples >= 3
        for _ in range(3):
            caller, service = fast_clock(), time.monotonic_ns()  # the same moment, on either clock
            assert abs(estimate.to_service(caller) - service) < estimate.uncertainty_ns + 1 * MS
            with frozen(client, "cam0"):  # no frame stored between the answer and the ring's frames read after it
                t_star = fast_clock() - 100 * MS
                frame = client.image("cam0", at=t_star, wait="none")
                mapped = client.clocks[medium.endpoint].to_service(t_star)
                nearest = _nearest_in_ring(client, "cam0", mapped)
            assert abs(mapped - round(t_star / (1 + DRIFT_PPM * 1e-6))) < estimate.uncertainty_ns + 1 * MS
            assert frame.service_t_capture == nearest
