"""The Foxglove live view (fxis run --foxglove): a real service, its Foxglove process, and
a WebSocket client in the test speaking the Foxglove protocol, as the Foxglove app does.
Messages are decoded by the schema the server advertises (protobuf), like the app."""

from __future__ import annotations

import base64
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import time

import numpy as np
import pytest
from websockets.sync.client import connect

from fxis_shm import read_stamp
from fxis_shm.service.launch import free_tcp_port

from ..conftest import fxis, fxis_run_alone, wait_until
from ..foxglove_decode import message_class
from .conftest import SMALL, module_services

pytestmark = pytest.mark.integration

# foxglove-sdk 0.30 speaks "foxglove.sdk.v1"; earlier servers "foxglove.websocket.v1"
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01  # opcode of a binary message: u32 subscription id, u64 log time (ns), payload
CAMERAS = ["--camera", "a=synthetic:fps=20,width=320,height=240", "--camera", f"b=synthetic:fps=10,{SMALL}"]
SIZES = {"a": (320, 240), "b": (64, 48)}
TOPICS = {"/a/image", "/b/image", "/fxis/status"}


class FoxgloveClient:
    """The app's side of the protocol: advertised channels, subscriptions, decoded messages."""

    def __init__(self, url: str, **options):
        self.ws = connect(
            url, subprotocols=SUBPROTOCOLS, open_timeout=10, close_timeout=2, max_size=None, **options
        ).__enter__()
        self.channels: dict[str, dict] = {}  # topic -> advertised channel
        self.subscriptions: dict[int, dict] = {}  # subscription id -> channel
        self.texts: list[dict] = []  # JSON messages other than advertise
        self._decoders: dict[int, type] = {}

    def close(self) -> None:
        self.ws.__exit__(None, None, None)

    def receive(self, timeout: float = 10.0):
        """The next message: a JSON op (dict), or (channel, log time ns, payload) of data."""
        message = self.ws.recv(timeout=timeout)
        if isinstance(message, str):
            op = json.loads(message)
            if op["op"] == "advertise":
                self.channels.update({c["topic"]: c for c in op["channels"]})
            else:
                self.texts.append(op)
            return op
        assert message[0] == MESSAGE_DATA, f"unexpected binary opcode {message[0]}"
        subscription, log_time = struct.unpack_from("<IQ", message, 1)
        return self.subscriptions[subscription], log_time, message[13:]

    def until(self, predicate, timeout: float = 20.0, what: str = "a message"):
        """Receive until ``predicate(message)`` is truthy; its value. Fails after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"timed out after {timeout} s waiting for {what}")
            try:
                value = predicate(self.receive(timeout=left))
            except TimeoutError:
                continue
            if value:
                return value

    def subscribe(self, topics) -> None:
        ids = {len(self.subscriptions) + i: self.channels[t] for i, t in enumerate(sorted(topics))}
        self.subscriptions.update(ids)
        self.ws.send(
            json.dumps({"op": "subscribe", "subscriptions": [{"id": i, "channelId": c["id"]} for i, c in ids.items()]})
        )

    def decode(self, channel: dict, payload: bytes):
        """A protobuf message by the channel's advertised schema (a FileDescriptorSet), or JSON."""
        if channel["encoding"] == "json":
            return json.loads(payload)
        assert channel["encoding"] == "protobuf" and channel["schemaEncoding"] == "protobuf"
        if channel["id"] not in self._decoders:
            self._decoders[channel["id"]] = message_class(channel["schemaName"], base64.b64decode(channel["schema"]))
        return self._decoders[channel["id"]].FromString(payload)


def foxglove_client(url: str, wait) -> FoxgloveClient:
    """A client once the server listens (it starts after the service answers)."""

    def attempt():
        try:
            return FoxgloveClient(url)
        except OSError:  # refused: not listening yet
            return None

    return wait(attempt, timeout=30, interval=0.1, what=f"the Foxglove server at {url}")


SERVED = [*CAMERAS, "--restart-limit", "0", "--slots", "100"]  # 100 slots: 5 s of a's frames


@pytest.fixture(scope="module")
def served():
    """A service with two cameras and its Foxglove server, shared by the tests that only read
    from it; yields (service, connected client)."""
    port = free_tcp_port()
    for (svc,) in module_services([*SERVED, "--foxglove", f"127.0.0.1:{port}"]):
        yield from _connected(svc, port)


@pytest.fixture
def served_to_set(start_service):
    """A test's own, for the test that sets the server's rate."""
    port = free_tcp_port()
    yield from _connected(start_service(*SERVED, "--foxglove", f"127.0.0.1:{port}"), port)


def _connected(svc, port: int):
    client = foxglove_client(f"ws://127.0.0.1:{port}", wait_until)
    client.until(lambda _: TOPICS <= set(client.channels), what="every channel advertised")
    yield svc, client
    client.close()


def images(client: FoxgloveClient, wanted: dict[str, int], timeout: float = 20.0) -> dict[str, list]:
    """Decoded messages per topic, until each has its ``wanted`` number: [(log time, message)]."""
    got: dict[str, list] = {topic: [] for topic in wanted}

    def take(message):
        if isinstance(message, tuple):
            channel, log_time, payload = message
            got.setdefault(channel["topic"], []).append((log_time, client.decode(channel, payload)))
        return all(len(got[t]) >= n for t, n in wanted.items())

    client.until(take, timeout, what=f"messages {wanted}")
    return got


def test_a_channel_per_camera_and_one_for_the_status_are_advertised(served):
    svc, client = served
    assert set(client.channels) == TOPICS
    for name in SIZES:
        channel = client.channels[f"/{name}/image"]
        assert channel["schemaName"] == "foxglove.RawImage" and channel["encoding"] == "protobuf"
    assert client.channels["/fxis/status"]["encoding"] == "json"


def test_images_are_the_cameras_frames_stamped_with_their_capture_time(served):
    svc, client = served
    client.subscribe(TOPICS)
    got = images(client, {"/a/image": 3, "/b/image": 3, "/fxis/status": 1})
    with svc.client() as service:
        times = service.frame_times()
        now = service.time()
    i_id, i_t = times["columns"].index("frame_id"), times["columns"].index("t_capture")
    for name, (width, height) in SIZES.items():
        in_ring = {row[i_id]: row[i_t] for row in times["cameras"][name]["frames"]}
        messages = [m for _, m in got[f"/{name}/image"]]
        captured = [m.timestamp.seconds * 10**9 + m.timestamp.nanos for m in messages]
        assert captured == sorted(set(captured)), "each frame once, oldest first"
        for m, t_capture in zip(messages, captured):
            assert (m.width, m.height, m.encoding, m.frame_id) == (width, height, "mono8", name)
            assert m.step == width and len(m.data) == width * height
            image = np.frombuffer(m.data, np.uint8).reshape(height, width)
            # the pixels are the frame whose capture time the message carries, in the service's clock
            frame_id = read_stamp(image)
            assert frame_id is not None, f"{name}: no frame stamp in the picture"
            assert in_ring.get(frame_id, t_capture) == t_capture  # where still in the ring
            assert 0 < now - t_capture < 60 * 10**9
        assert in_ring.get(read_stamp(image)) == captured[-1], f"{name}: the newest frame left the ring"
    status = got["/fxis/status"][0][1]
    assert status["service_ok"] and set(status["status"]["cameras"]) == set(SIZES)


def test_the_viewer_sets_the_rate_and_a_bad_one_is_refused(served_to_set):
    svc, client = served_to_set
    client.ws.send(json.dumps({"op": "getParameters", "parameterNames": ["rate_hz"], "id": "get"}))
    values = client.until(
        lambda m: isinstance(m, dict) and m.get("op") == "parameterValues" and m, what="the rate parameter"
    )
    assert values["parameters"] == [{"name": "rate_hz", "type": "float64", "value": 10.0}]
    client.ws.send(
        json.dumps(
            {"op": "setParameters", "id": "bad", "parameters": [{"name": "rate_hz", "type": "float64", "value": -1.0}]}
        )
    )
    refused = client.until(
        lambda m: isinstance(m, dict) and m.get("op") == "status" and m, what="a status message refusing the rate"
    )
    assert "rate_hz must be" in refused["message"]
    client.ws.send(
        json.dumps(
            {"op": "setParameters", "id": "set", "parameters": [{"name": "rate_hz", "type": "float64", "value": 2.0}]}
        )
    )
    set_to = client.until(lambda m: isinstance(m, dict) and m.get("id") == "set" and m, what="the new rate confirmed")
    assert set_to["parameters"][0]["value"] == 2.0
    client.subscribe(["/a/image"])  # a camera at 20 fps, sent at 2 pictures a second
    # Pictures sent (log time: when the server sent them) over 8 s from the second one on (the
    # first may have been sent before the rate changed): 2 a second is 16 (17 counting both
    # ends). The server never catches up on pictures it was late for, so a loaded machine can
    # only make fewer: at least 8 (1 a second) is asked. 3 a second would be 24, 4 would be 32.
    window_ns = 8 * 10**9
    sent = []

    def window_done(message):
        if isinstance(message, tuple) and message[0]["topic"] == "/a/image":
            sent.append(message[1])
        return len(sent) >= 2 and sent[-1] - sent[1] > window_ns

    client.until(window_done, timeout=30, what="8 s of pictures")
    in_window = [t for t in sent[1:] if t - sent[1] <= window_ns]
    assert 8 <= len(in_window) <= 17, f"{len(in_window)} pictures in 8 s at 2 a second: {np.diff(in_window) / 1e9} s"


def test_a_killed_foxglove_process_is_restarted(start_service, wait):
    port = free_tcp_port()
    svc = start_service(*CAMERAS, "--foxglove", f"127.0.0.1:{port}")
    foxglove_client(f"ws://127.0.0.1:{port}", wait).close()
    with svc.client() as service:
        process = service.status()["supervisor"]["processes"]["foxglove"]
        assert process["state"] == "running"
        os.kill(process["pid"], signal.SIGKILL)
        wait(
            lambda: service.status()["supervisor"]["processes"]["foxglove"]["restarts"] == 1,
            timeout=20,
            what="the Foxglove process restarted",
        )
    client = foxglove_client(f"ws://127.0.0.1:{port}", wait)
    try:
        client.until(lambda _: TOPICS <= set(client.channels), what="every channel advertised again")
    finally:
        client.close()


@pytest.mark.parametrize(
    "args, words",
    [
        (["--foxglove", "nowhere"], ["foxglove 'nowhere'", "HOST:PORT"]),
        (["--foxglove", "127.0.0.1:8765", "--foxglove-rate", "0"], ["foxglove_rate must be", "> 0"]),
        (["--foxglove", "127.0.0.1:8765", "--foxglove-rate", "abc"], ["foxglove_rate must be"]),
    ],
)
def test_bad_foxglove_settings_are_refused_naming_them(args, words):
    result = fxis("run", "--http", "off", *args)
    assert result.returncode == 2, result.stderr
    assert all(w in result.stderr for w in words), result.stderr


def test_without_the_sdk_the_message_names_the_extra(tmp_path):
    shadow = tmp_path / "foxglove"  # a foxglove package that cannot be imported, first on the path
    shadow.mkdir()
    (shadow / "__init__.py").write_text("raise ImportError(\"No module named 'foxglove'\")\n")
    env = {**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    result = subprocess.run(
        [sys.executable, "-m", "fxis_shm.cli", "run", "--http", "off", "--foxglove", "127.0.0.1:8765"],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
    )
    assert result.returncode == 2, result.stderr
    assert "foxglove-sdk" in result.stderr and "fxis-shm[foxglove]" in result.stderr, result.stderr


# Real time: "no frame dropped" holds while the camera's worker gets the CPU; one held up longer
# than its driver's buffers (12 frames; the parallel pass, 2 cores) drops frames, viewers or not.
@pytest.mark.realtime
def test_a_viewer_that_stops_reading_holds_up_nobody(start_service, wait):
    port = free_tcp_port()
    svc = start_service(
        "--camera",
        "a=synthetic:fps=20,width=1280,height=960",  # 1.2 MB pictures
        "--foxglove",
        f"127.0.0.1:{port}",
    )
    url = f"ws://127.0.0.1:{port}"
    reader = foxglove_client(url, wait)
    # a viewer that subscribes and never reads: a small receive buffer and a queue of one
    # message, so the server's socket to it fills within a few pictures
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", port))
    stalled = FoxgloveClient(url, sock=sock, max_queue=1)
    try:
        stalled.until(lambda _: "/a/image" in stalled.channels, what="the channels advertised")
        stalled.subscribe(["/a/image"])
        reader.until(lambda _: "/a/image" in reader.channels, what="the channels advertised")
        with svc.client() as service:
            before = service.status()["cameras"]["a"]
        reader.subscribe(["/a/image"])
        images(reader, {"/a/image": 50}, timeout=40)  # 60 MB of pictures the other reads none of
        with svc.client() as service:
            after = service.status()["cameras"]["a"]
    finally:
        stalled.close()
        reader.close()
    assert after["frames_stored"] > before["frames_stored"]
    assert after["frames_dropped"] == before["frames_dropped"]


def test_a_port_in_use_stops_start_up_naming_the_foxglove_server():
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        result = fxis_run_alone("--camera", f"a=synthetic:{SMALL}", "--http", "off", "--foxglove", f"127.0.0.1:{port}")
    assert result.returncode == 2  # a bad setting, found before anything started (issue 24)
    assert f"--foxglove 127.0.0.1:{port}" in result.stderr and "in use" in result.stderr, result.stderr
