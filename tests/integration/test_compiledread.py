"""The compiled read (fxis_shm/shm/_fastpick.c): the same-host client's and the coordinator's
answers to the common requests, made by one C call over the real rings, are the engine's answers;
whatever it does not settle goes to the engine, which answers or fails as it always did.

The C decision itself is checked against the Python one by tests/unit/test_pickcore.py.
"""

import os
import signal
import time

import numpy as np
import pytest
import zmq

from fxis_shm import Client, read_stamp
from fxis_shm.core.snapshot import SLOT
from fxis_shm.errors import CameraDown, ServiceError, UnknownCamera
from fxis_shm.shm import fastpick, naming
from fxis_shm.shm.ring import FrameLayout, RingReader, RingWriter
from fxis_shm.shm.ringheader import HEADER_BYTES
from fxis_shm.wire.protocol import encode_request

from ..conftest import wait_until
from .conftest import SMALL, child_pids

pytestmark = pytest.mark.integration
PURE = os.environ.get("FXIS_PURE_PYTHON") == "1"
compiled = pytest.mark.skipif(PURE, reason="FXIS_PURE_PYTHON=1 turns the compiled read off (the first test checks)")
SETTINGS = {"sync": "joint", "wait": "auto", "sync_tolerance_ms": 2.0, "horizon_ms": 10_000.0}
# t* this far back: its frames are stored, also on an emulated CPU (scripts/test-aarch64.sh),
# where 60 ms left 2 of 61 requests to the engine (the frame after t* not stored yet), and
# with a camera's worker held up some 100 ms in the parallel pass (the counts of compiled
# answers are exact); every service here holds 60 slots, 1.2 s at 50 fps
PAST_NS = 400_000_000


def wait_for_the_past(client) -> None:
    """Until every camera's ring holds frames from before t* = now - PAST_NS (the cameras
    start at different moments: one with 6 frames is 120 ms deep at 50 fps)."""

    def deep_enough() -> bool:
        cameras = client.status()["cameras"].values()
        return all(c.get("frames_stored", 0) >= PAST_NS * c["fps"] / 1e9 + 3 for c in cameras)

    wait_until(deep_enough, what=f"every ring to hold {PAST_NS / 1e6:.0f} ms")


# scripts/test-aarch64.sh on an emulated CPU (qemu, 10-50x slower): cameras there run late on
# their own schedule (2 of 61 requests twice), and the wait policy hands such a request to the
# engine; the count of compiled answers is exact on a real CPU only
EMULATED = os.environ.get("FXIS_EMULATED_CPU") == "1"


def stored_t(client) -> int:
    """A t* whose frames and each camera's next one are stored: two periods of the slowest
    camera (30 fps) before the newest frame of the camera furthest behind. ("now minus a
    margin" is not enough on an emulated CPU, where the cameras lag their own schedule.)"""
    listing = client.frame_times()
    column = listing["columns"].index("t_capture")
    return min(info["frames"][-1][column] for info in listing["cameras"].values()) - 70_000_000


def ids(tuple_):
    return {cam: frame.frame_id for cam, frame in tuple_.items()}


def engine_answer(client, op, **fields):
    """The same request answered by the engine over the same rings (the client's own LocalReads)."""
    header, images, _ = client._reads.answer(op, fields, time.monotonic_ns() + 2_000_000_000)
    return {m["camera"]: m["frame_id"] for m in header["frames"]}, header


@pytest.fixture(scope="module")
def three_cameras():
    from .conftest import module_service

    yield from module_service(
        [
            "--camera",
            f"a=synthetic:fps=50,{SMALL}",
            "--camera",
            f"b=synthetic:fps=30,phase_ms=7,{SMALL}",
            "--camera",
            f"c=synthetic:fps=50,phase_ms=3,{SMALL}",
            "--slots",
            "60",  # 1.2 s at 50 fps: t* up to PAST_NS + 0.1 s back stays in the rings
        ]
    )


def test_the_compiled_read_is_on_unless_fxis_pure_python_turns_it_off(three_cameras):
    """Built (`make setup`), it answers; with FXIS_PURE_PYTHON=1 the engine answers everything."""
    assert fastpick.AVAILABLE != PURE, "the compiled read is not built: `make setup` builds it"
    with Client(three_cameras.endpoint, local="require") as client:
        wait_for_the_past(client)
        client.latest()  # opens the rings
        frames = client.tuple(at=time.monotonic_ns() - PAST_NS)
    assert frames.path == "local" and client.paths["compiled"] == (0 if PURE else 1)


@compiled
def test_the_compiled_read_answers_as_the_engine_does(three_cameras):
    """Many requests, each answered by the compiled read and by the engine over the same rings
    at the same moment (the rings hold every frame involved): the same frames, the same skew."""
    with Client(three_cameras.endpoint, local="require") as client:
        wait_until(lambda: client.status()["cameras"]["b"].get("frames_stored", 0) > 10)
        client.latest()  # opens the rings
        asks = [
            dict(),
            dict(sync="independent"),
            dict(wait="none"),
            dict(cameras=["c", "a"]),
            dict(cameras=["b", "c", "a"], sync="joint"),
            dict(cameras=["b"]),
        ]
        compared = 0
        for step in range(60):
            fields = asks[step % len(asks)]
            at = stored_t(client) - step * 1_700_000  # every phase against the frames
            fast = client.tuple(at=at, **fields)
            by_engine, header = engine_answer(client, "tuple", at=at, **fields)
            assert list(fast) == list(fields.get("cameras") or ["a", "b", "c"])  # in the order asked
            assert ids(fast) == by_engine, fields
            assert fast.skew_ns == header["skew_ns"]
            assert all(read_stamp(f.image) == f.frame_id for f in fast.values())
            compared += 1
        image = client.image("b", at=at)
        assert image.frame_id == engine_answer(client, "image", camera="b", at=at)[0]["b"]
    if EMULATED:  # see EMULATED: every answer was compared above, whoever gave it
        assert client.paths["compiled"] >= 0.9 * (compared + 1), client.paths
    else:
        assert client.paths["compiled"] == compared + 1, client.paths  # not the first latest(): it opened the rings
    assert client.paths["local"] == compared + 2, client.paths


@compiled
def test_zero_copy_views_are_the_slots_and_say_when_they_are_overwritten(three_cameras):
    with Client(three_cameras.endpoint, local="require") as client:
        wait_for_the_past(client)
        client.latest()
        views = client.tuple(at=time.monotonic_ns() - PAST_NS, copy=False)
        copies = client.tuple(at=views.t_request)
        assert client.paths["compiled"] == 2
        for cam in views:
            assert not views[cam].image.flags.writeable
            np.testing.assert_array_equal(views[cam].image, copies[cam].image)
        assert views.still_valid()
        slots = client.status()["cameras"]["a"]["ring_slots"]
        wait_until(lambda: not views["a"].still_valid(), timeout=slots / 50 * 3, what="the slot to be overwritten")
        assert copies.still_valid()  # a copy stays valid


@compiled
def test_a_copy_lands_in_an_array_nobody_else_holds(three_cameras):
    """The pool hands an array out again only once nothing refers to it: a frame kept, or a view
    of it kept, is never overwritten by a later request."""
    with Client(three_cameras.endpoint, local="require") as client:
        wait_for_the_past(client)
        client.latest()
        kept = client.latest(["a"])["a"]
        kept_id, view = kept.frame_id, kept.image[2:, :]
        pixels = kept.image.copy()
        for _ in range(8):
            wait_until(lambda: client.latest(["a"])["a"].frame_id != kept_id, what="a newer frame")
        np.testing.assert_array_equal(kept.image, pixels)
        kept.release()
        np.testing.assert_array_equal(view, pixels[2:, :])  # the view still holds the array
        address = client.latest(["a"])["a"].image.__array_interface__["data"][0]
        # that array went back to the pool when the tuple holding it went: the next copy reuses it
        assert client.latest(["a"])["a"].image.__array_interface__["data"][0] == address


@compiled
def test_what_the_compiled_read_does_not_settle_gets_the_engines_answer(three_cameras):
    with Client(three_cameras.endpoint, local="require") as client:
        wait_for_the_past(client)
        client.latest()
        served = client.paths["compiled"]
        now = time.monotonic_ns()
        with pytest.raises(ServiceError, match="older than the oldest") as too_old:
            client.tuple(at=1)  # the clock's first ns: older than any frame, on a machine booted a minute ago too
        with pytest.raises(ServiceError, match="horizon") as too_late:
            client.tuple(at=now + 3_600_000_000_000)
        assert too_old.value.code == too_late.value.code == "OUT_OF_RANGE"
        with pytest.raises(UnknownCamera):
            client.tuple(["a", "nope"], at=now - PAST_NS)
        waited = client.tuple(at=time.monotonic_ns() + 30_000_000)  # a future t*: the engine waits
        assert waited.path == "local"
        assert client.tuple(at=now - PAST_NS, max_skew_ms=50.0).path == "local"  # a skew limit
        assert client.paths["compiled"] == served


@compiled
def test_a_stopped_camera_is_the_engines_to_report(start_service):
    svc = start_service(
        "--camera", f"a=synthetic:fps=50,{SMALL}", "--camera", f"b=synthetic:fps=50,{SMALL}", "--slots", "60"
    )
    with Client(svc.endpoint, local="require", timeout=5.0) as client:
        wait_for_the_past(client)
        client.latest()  # opens the rings
        client.latest()
        assert client.paths["compiled"] == 1
        b_pid = client.status()["cameras"]["b"]["writer_pid"]
        assert b_pid in child_pids(svc, "camera")
        os.kill(b_pid, signal.SIGSTOP)
        try:
            wait_until(lambda: _down(client), timeout=10.0, what="the stopped camera to count as down")
            partial = client.tuple(at=time.monotonic_ns() - PAST_NS, partial=True)
            assert partial.missing == ["b"] and list(partial) == ["a"]
        finally:
            os.kill(b_pid, signal.SIGCONT)
        wait_until(lambda: not _down(client), timeout=10.0, what="the camera to be back")
        assert client.tuple(at=time.monotonic_ns() - PAST_NS).path == "local"


def _down(client) -> bool:
    try:
        client.tuple(at=time.monotonic_ns() - PAST_NS)
    except CameraDown:
        return True
    return False


@compiled
def test_the_coordinator_answers_the_common_requests_compiled(three_cameras):
    """A client elsewhere (local="off") gets from the coordinator's compiled answer the frames
    and reply fields the engine gives, and the coordinator counts them."""
    with Client(three_cameras.endpoint, local="off") as remote, Client(three_cameras.endpoint) as local:
        wait_until(lambda: remote.status()["cameras"]["b"].get("frames_stored", 0) > 10)
        before = remote.status()["requests_compiled"]
        at = stored_t(remote)
        by_wire = remote.tuple(["c", "b"], at=at)
        local.latest()
        by_engine, header = engine_answer(local, "tuple", cameras=["c", "b"], at=at)
        assert ids(by_wire) == by_engine and list(by_wire) == ["c", "b"]
        assert by_wire.skew_ns == header["skew_ns"] and by_wire.t_request == at
        timing = by_wire.timing
        order = [timing[k] for k in ("received", "waited", "searched", "copied", "sent")]
        assert order == sorted(order) and set(timing["cameras"]) == {"b", "c"}
        assert all(read_stamp(f.image) == f.frame_id for f in by_wire.values())
        assert remote.latest().path == "network"
        assert remote.image("a", at=at).frame_id == engine_answer(local, "image", camera="a", at=at)[0]["a"]
        remote.tuple(at=at, max_skew_ms=50.0)  # the engine's
        assert remote.status()["requests_compiled"] == before + 3


@compiled
def test_the_coordinators_compiled_answer_keeps_the_engines_limits(start_service, tmp_path):
    """With another client's request waiting, a stored t* is still answered compiled; once
    max_pending requests wait, it is refused BUSY as the engine refuses any other."""
    config = tmp_path / "limits.toml"
    config.write_text("max_pending = 2\n")
    svc = start_service("--camera", f"a=synthetic:fps=50,{SMALL}", "--config", str(config), "--slots", "60")
    waiting = []
    try:
        with Client(svc.endpoint, local="off", timeout=5.0) as remote:
            wait_for_the_past(remote)
            future = remote.time() + 3_000_000_000
            for n in (1, 2):
                waiting.append(zmq.Context.instance().socket(zmq.DEALER))
                waiting[-1].setsockopt(zmq.LINGER, 0)
                waiting[-1].connect(svc.endpoint)
                waiting[-1].send_multipart([b"", *encode_request("tuple", id=n, at=future)])
                wait_until(lambda n=n: remote.status()["pending"] == n, what=f"{n} requests waiting")
                compiled_before = remote.status()["requests_compiled"]
                if n == 1:
                    assert remote.tuple(at=time.monotonic_ns() - PAST_NS).path == "network"
                    assert remote.status()["requests_compiled"] == compiled_before + 1
            with pytest.raises(ServiceError, match="2 requests are waiting already") as refused:
                remote.tuple(at=time.monotonic_ns() - PAST_NS)
            assert refused.value.code == "BUSY"
            assert remote.status()["requests_compiled"] == compiled_before
    finally:
        for sock in waiting:
            sock.close()


# ---- the C reader over rings made here (real shared memory, no service) ----


@pytest.fixture
def ring(request):
    service = f"fast{os.getpid()}-{request.node.name[-12:]}"
    writer = RingWriter(service, "cam", FrameLayout(4, 8), slots=4, nominal_period_ns=10_000_000)
    reader = RingReader(service, "cam", with_semaphore=False)
    yield service, writer, reader
    reader.close()
    writer.close()
    naming.remove_leftovers(service)


def stored(writer, count: int) -> int:
    """``count`` frames written 10 ms apart, the last captured now; returns its capture time."""
    t = time.monotonic_ns() - (count - 1) * 10_000_000
    for k in range(count):
        writer.write(np.full((4, 8), k, np.uint8), frame_id=k, t_capture=t + k * 10_000_000)
    return t + (count - 1) * 10_000_000


@compiled
def test_a_record_being_rewritten_is_left_to_the_engine(ring):
    _, writer, reader = ring
    newest = stored(writer, 4)
    picker = fastpick.Picker(["cam"], [reader], SETTINGS, "monotonic", 1 << 20)
    assert picker.pick(None, fastpick.TUPLE, newest, None, None, True)[4][0][2] == 3
    seq = np.ndarray((4,), dtype="<u8", buffer=writer._mm, offset=HEADER_BYTES, strides=(SLOT.itemsize,))
    seq[3] += 1  # write 3 (slot 3) shows as being written again
    assert picker.pick(None, fastpick.TUPLE, newest, None, None, True) is None
    seq[3] -= 1
    assert picker.pick(None, fastpick.LATEST, 0, None, None, False)[4][0][2] == 3


@compiled
def test_a_replaced_ring_says_so(ring):
    service, writer, reader = ring
    newest = stored(writer, 2)
    picker = fastpick.Picker(["cam"], [reader], SETTINGS, "monotonic", 1 << 20)
    assert picker.pick(None, fastpick.TUPLE, newest, None, None, False) is not None and not picker.retired
    RingWriter(service, "cam", FrameLayout(8, 8), slots=4).close()  # another layout: the old ring retires
    assert picker.pick(None, fastpick.TUPLE, newest, None, None, False) is None and picker.retired
