"""Requests against a real service: frames are the frames their metadata names,
many clients are served at once, and a waiting request delays no one."""

import os
import signal

import pytest
import zmq

from fxis_shm import Client, RequestTimeout, read_stamp
from fxis_shm.wire.protocol import decode_reply, encode_request
from fxis_shm.wire.statusdoc import ProcessState, StatusDocument

from ..conftest import run_in_threads
from .conftest import child_pids

pytestmark = pytest.mark.integration


def assert_stamps_match(frames):
    for name, frame in frames.items():
        assert read_stamp(frame.image) == frame.frame_id, f"{name}: pixels are not frame {frame.frame_id}"


def test_tuple_pixels_are_the_frames_the_metadata_names(two_cameras):
    with two_cameras.client() as client:
        for _ in range(5):
            frames = client.tuple()
            assert set(frames) == {"cam0", "cam1"}
            assert_stamps_match(frames)
            assert frames.skew_ns == abs(frames["cam0"].t_capture - frames["cam1"].t_capture)
            for frame in frames.values():
                assert frame.image.shape == (48, 64) and frame.image.dtype.name == "uint8"
                assert frame.t_capture <= frame.t_available <= frame.t_stored
                assert frame.generation == 1


def test_image_and_latest_return_stamped_frames(two_cameras):
    with two_cameras.client() as client:
        frame = client.image("cam1")
        assert frame.camera == "cam1" and read_stamp(frame.image) == frame.frame_id
        newest = client.latest()
        assert_stamps_match(newest)
        assert newest["cam0"].frame_id >= frame.frame_id - 1


def test_timing_record_is_ordered(two_cameras):
    with two_cameras.client() as client:
        timing = client.tuple().timing
    order = [timing[k] for k in ("received", "waited", "searched", "copied", "sent")]
    assert order == sorted(order)
    assert set(timing["cameras"]) == {"cam0", "cam1"}


def test_status_and_time(two_cameras):
    with two_cameras.client() as client:
        before = client.time()
        status = client.status()
        after = client.time()
    assert before <= status["now"] <= after
    assert status["uptime_s"] > 0
    for cam in ("cam0", "cam1"):
        info = status["cameras"][cam]
        assert info["alive"] and info["kind"] == "synthetic"
        assert info["shape"] == [48, 64] and info["ring_slots"] == 20 and info["generation"] == 1
        assert info["frames_stored"] > 0 and info["frames_dropped"] >= 0
        assert info["fps"] == pytest.approx(50, rel=0.05)


def test_the_status_reply_has_the_shape_its_typed_dict_names(two_cameras):
    """wire/statusdoc.py is what the type checker holds the coordinator's status to: the reply
    carries every field StatusDocument names and no other (besides the reply header's), and the
    supervisor's process entries the fields of ProcessState."""
    req = zmq.Context.instance().socket(zmq.REQ)
    req.setsockopt(zmq.LINGER, 0)
    req.setsockopt(zmq.RCVTIMEO, 5000)
    req.connect(two_cameras.endpoint)
    try:
        req.send_multipart(encode_request("status", id=7))
        header, _ = decode_reply(req.recv_multipart())
    finally:
        req.close()
    assert set(header) - {"v", "id", "ok"} == set(StatusDocument.__annotations__)
    assert header["supervisor"] is not None and header["supervisor"]["processes"]
    for process in header["supervisor"]["processes"].values():
        assert set(process) == set(ProcessState.__required_keys__ | ProcessState.__optional_keys__)


def test_many_clients_at_once(two_cameras):
    errors, served = [], []

    def worker():
        try:
            with two_cameras.client(timeout=5.0) as client:
                for _ in range(5):
                    frames = client.tuple()
                    assert_stamps_match(frames)
                    served.append(frames)
        except Exception as exc:  # collected and reported below
            errors.append(exc)

    run_in_threads(worker, 16, timeout=30)
    assert not errors, errors[:3]
    assert len(served) == 16 * 5


def test_a_waiting_request_does_not_delay_other_clients(two_cameras):
    ctx = zmq.Context.instance()
    waiter = ctx.socket(zmq.DEALER)
    waiter.setsockopt(zmq.LINGER, 0)
    waiter.connect(two_cameras.endpoint)
    try:
        with two_cameras.client() as other:
            t_sent = other.time()
            t_future = t_sent + 1_500_000_000  # frames for this do not exist for 1.5 s
            waiter.send_multipart([b""] + encode_request("tuple", id=1, at=t_future))
            for _ in range(5):
                other.status()  # answered while the tuple request waits
            assert waiter.poll(0) == 0, "the waiting request was answered before its frames existed"
        assert waiter.poll(5000), "the waiting request was never answered"
        header, images = decode_reply(waiter.recv_multipart()[1:])
    finally:
        waiter.close()
    # answered with the frames of t*, captured after the request was sent, not with an error
    assert header["ok"] is True and header["id"] == 1, header
    assert header["t_request"] == t_future
    frames = {meta["camera"]: (meta, image) for meta, image in zip(header["frames"], images)}
    assert set(frames) == {"cam0", "cam1"}
    for meta, image in frames.values():
        assert read_stamp(image) == meta["frame_id"]
        assert meta["t_capture"] > t_sent + 1_000_000_000  # nearest to t*, not to the moment of sending


def test_req_socket_clients_are_served(two_cameras):
    req = zmq.Context.instance().socket(zmq.REQ)
    req.setsockopt(zmq.LINGER, 0)
    req.setsockopt(zmq.RCVTIMEO, 5000)
    req.connect(two_cameras.endpoint)
    try:
        req.send_multipart(encode_request("time", id="abc"))
        header = req.recv_multipart()[0]
    finally:
        req.close()
    assert b'"ok": true' in header and b'"id": "abc"' in header


def test_client_survives_a_timeout(two_cameras):
    """A coordinator that stalls makes a request time out; once it resumes, the
    same client works and the late reply to the timed-out request is skipped."""
    (coordinator,) = child_pids(two_cameras, "coordinator")
    with two_cameras.client(timeout=0.3) as client:
        os.kill(coordinator, signal.SIGSTOP)
        try:
            with pytest.raises(RequestTimeout):
                client.time()
        finally:
            os.kill(coordinator, signal.SIGCONT)
        client.timeout = 5.0  # the coordinator just resumed, on a machine that may be busy
        assert client.status()["service"] == two_cameras.name
        assert_stamps_match(client.latest())


def test_client_without_a_service_times_out_clearly():
    with Client("tcp://127.0.0.1:9", timeout=0.3) as client:
        with pytest.raises(RequestTimeout, match="no reply"):
            client.status()
        with pytest.raises(RequestTimeout):
            client.status()
