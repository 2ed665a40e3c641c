"""Fault injection with real processes: kill -9 of a camera worker and of the
coordinator, partial tuples, per-client limits, and torn reads under stress."""

import json
import os
import signal
import threading
import time

import pytest
import zmq

from fxis_shm import CameraDown, Client, Overwritten, RequestTimeout, ServiceError, read_stamp
from fxis_shm.wire.protocol import encode_request

from ..conftest import wait_until
from .conftest import SMALL, child_pids

pytestmark = pytest.mark.integration


def until_served(client, request, timeout=20.0):
    """Retry ``request(client)`` until it succeeds; returns (result, seconds it took)."""
    start = time.monotonic()
    while True:
        try:
            return request(client), time.monotonic() - start
        except (RequestTimeout, ServiceError):
            if time.monotonic() - start > timeout:
                raise
            time.sleep(0.02)


def test_kill_9_of_a_camera_worker(start_service):
    svc = start_service("--camera", f"a=synthetic:fps=50,{SMALL}", "--camera", f"b=synthetic:fps=50,{SMALL}")
    with svc.client(timeout=2.0) as client:
        os.kill(client.status()["cameras"]["a"]["writer_pid"], signal.SIGKILL)
        wait_until(lambda: not client.status()["cameras"]["a"]["alive"], what="camera a to show down")
        with pytest.raises(CameraDown):  # during the outage: fails fast, with a code that says so
            client.image("a")
        partial = client.tuple(partial=True)
        assert partial.missing == ["a"] and set(partial) == {"b"}
        frame, _ = until_served(client, lambda c: c.image("a"))
        assert frame.generation == 2 and read_stamp(frame.image) == frame.frame_id

        # the supervisor notes "restarted" once it has read the worker's handshake, which may come
        # after the worker's first frames were served: waited for, with a deadline
        def restarted():
            status = client.status()
            events = status["supervisor"]["events"]
            return status if any("camera:a" == e["process"] and "restarted" in e["what"] for e in events) else None

        status = wait_until(restarted, what="the supervisor's 'restarted' event of camera a")
        assert status["cameras"]["a"]["restarts"] == 1


def test_kill_9_of_the_coordinator(start_service):
    svc = start_service("--camera", f"a=synthetic:fps=50,{SMALL}")
    (coordinator,) = child_pids(svc, "coordinator")  # on record before the service answered
    with svc.client(timeout=5.0) as client:
        before = client.image("a").frame_id
        client.timeout = 0.3  # the outage's own requests: short, as nobody will answer
        os.kill(coordinator, signal.SIGKILL)
        with pytest.raises(RequestTimeout):  # nobody answers during the outage; nothing hangs
            client.status()
        status, _ = until_served(client, lambda c: c.status())
        assert status["supervisor"]["processes"]["coordinator"]["restarts"] == 1
        for local in ("off", "auto"):  # through the new coordinator, and from the rings
            with svc.client(timeout=1.0) as fresh:
                fresh.local = local
                frame = fresh.image("a")
                assert frame.frame_id > before and read_stamp(frame.image) == frame.frame_id
    assert child_pids(svc, "coordinator") != [coordinator]


def test_same_host_reads_go_on_while_the_coordinator_hangs(start_service):
    svc = start_service("--camera", f"a=synthetic:fps=50,{SMALL}")
    (coordinator,) = child_pids(svc, "coordinator")  # on record before the service answered
    with svc.client(timeout=5.0) as client:
        before = client.image("a").frame_id  # learns the rings
        os.kill(coordinator, signal.SIGSTOP)
        try:
            client.timeout = 0.5  # nobody answers: the status times out soon
            with pytest.raises(RequestTimeout):
                client.status()
            client.timeout = 5.0  # the same-host wait needs no coordinator, only the camera
            later = client.image("a", at=client.image("a").t_capture + 100_000_000)  # a wait, too
        finally:
            os.kill(coordinator, signal.SIGCONT)
        assert later.frame_id > before and later.path == "local"
        assert read_stamp(later.image) == later.frame_id


def test_a_client_cannot_hog_the_pending_requests(start_service, tmp_path):
    config = tmp_path / "limits.toml"
    config.write_text("max_pending_per_client = 3\n")
    svc = start_service("--camera", f"a=synthetic:{SMALL}", "--config", str(config))
    sock = zmq.Context.instance().socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.connect(svc.endpoint)
    try:
        with svc.client() as other:
            future = other.time() + 5_000_000_000
            for i in range(4):
                sock.send_multipart([b""] + encode_request("tuple", id=i, at=future))
            assert sock.poll(5000)
            reply = sock.recv_multipart()
            assert b'"id": 3' in reply[1] and b"BUSY" in reply[1]
            assert other.tuple()["a"].frame_id >= 0  # other clients are served
    finally:
        sock.close()


def test_the_service_holds_at_most_max_pending_waiting_requests(start_service, tmp_path):
    """max_pending is service-wide: with 3 requests of three clients waiting, a fourth client's
    is refused BUSY at once; the others are served meanwhile, and the three are answered."""
    config = tmp_path / "limits.toml"
    config.write_text("max_pending = 3\n")
    svc = start_service("--camera", f"a=synthetic:fps=50,{SMALL}", "--config", str(config))
    socks = []
    try:
        with svc.client() as other:
            future = other.time() + 2_000_000_000
            for i in range(4):
                sock = zmq.Context.instance().socket(zmq.DEALER)
                sock.setsockopt(zmq.LINGER, 0)
                sock.connect(svc.endpoint)
                socks.append(sock)
                sock.send_multipart([b""] + encode_request("tuple", id=i, at=future))
                if i < 3:  # each waiting before the next is sent: the fourth is the one beyond the limit
                    wait_until(lambda n=i + 1: other.status()["pending"] == n, what=f"{i + 1} requests waiting")
            assert socks[3].poll(5000), "the request beyond max_pending was not answered at once"
            header = json.loads(socks[3].recv_multipart()[1])
            assert header["id"] == 3 and not header["ok"] and header["error"]["code"] == "BUSY", header
            assert "3 requests are waiting already" in header["error"]["message"]
            assert other.status()["pending"] == 3  # the service answers meanwhile; the three still wait
            assert [sock.poll(0) for sock in socks[:3]] == [0, 0, 0]
        for i, sock in enumerate(socks[:3]):
            assert sock.poll(10_000), f"waiting request {i} was never answered"
            header = json.loads(sock.recv_multipart()[1])
            assert header["id"] == i and header["ok"] is True and header["frames"], header
    finally:
        for sock in socks:
            sock.close()


OVERWRITTEN = "overwritten 3 times"  # the refusal after three torn copies of one request's frames
OLDER_NS = 1_800_000  # 0.9 periods at 500 fps: the frame before the newest, or the newest once that is gone


@pytest.mark.parametrize("local", ["off", "require"])
def test_torn_reads_never_reach_a_client(start_service, local):
    """Rings of 2 slots at 500 fps: the writer laps readers constantly. The service copies the
    frames (local="off") or the clients copy them from the rings themselves. Besides the next and
    the newest frame, each reader asks for the frame before the newest it saw: the one the writer
    overwrites next, so that copies are torn however fast they are made. Readers go on until
    copies were found torn and made again (the service's count, or the clients' ``paths["torn"]``)
    and enough frames were served: not one served frame is torn, and a request whose frames were
    overwritten three times is refused saying so (``Overwritten``, or ``OVERRUN`` with that
    message); any other error fails the test."""
    svc = start_service("--slots", "2", "--camera", "fast=synthetic:fps=500,width=512,height=256")
    errors, served, refused, clients, paths = [], [0], [0], [], set()
    stop = threading.Event()

    def older(client, at):
        """The frame at ``at``, or the newest again if the writer has already gone two frames on."""
        try:
            return client.image("fast", at=at)
        except ServiceError as exc:
            if exc.code != "OUT_OF_RANGE":
                raise
            return client.latest()["fast"]

    def reader():
        try:
            with Client(svc.endpoint, timeout=5.0, local=local) as client:
                clients.append(client)
                while not stop.is_set():
                    try:
                        newest = client.latest()["fast"]
                        frames = (newest, older(client, newest.t_capture - OLDER_NS), client.image("fast"))
                    except Overwritten as exc:
                        assert OVERWRITTEN in str(exc), exc
                        refused[0] += 1
                        continue
                    except ServiceError as exc:
                        if exc.code != "OVERRUN" or OVERWRITTEN not in exc.message:
                            raise
                        refused[0] += 1
                        continue
                    for frame in frames:
                        assert read_stamp(frame.image) == frame.frame_id, "a torn or wrong frame"
                        served[0] += 1
                        paths.add(frame.path)
        except Exception as exc:
            errors.append(exc)

    def torn_copies() -> int:
        if local == "off":
            with svc.client() as client:
                return client.status()["cameras"]["fast"]["torn_reads"]
        return sum(client.paths["torn"] for client in list(clients))

    threads = [threading.Thread(target=reader) for _ in range(8)]
    for thread in threads:
        thread.start()
    try:
        wait_until(
            lambda: errors or (served[0] >= 1200 and torn_copies() > 0),
            timeout=90,  # a loaded machine takes longer; an idle one tears a copy now and then
            interval=0.1,
            what="1200 frames served and torn copies found",
        )
        torn = torn_copies()
    finally:
        stop.set()
        for thread in threads:
            thread.join(30)
    assert not any(t.is_alive() for t in threads), "a reader did not finish"
    assert not errors, errors[:3]
    assert paths == {"network" if local == "off" else "local"}
    with svc.client() as client:
        status = client.status()["cameras"]["fast"]
    assert status["frames_stored"] > 100  # wrapped many times
    print(
        f"torn-read stress ({paths.pop()} path): {served[0]} frames served, {torn} torn copies "
        f"found and made again, {refused[0]} requests refused, {status['frames_stored']} frames written"
    )
