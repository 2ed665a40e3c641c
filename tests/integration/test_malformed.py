"""Malformed requests each get an error reply, and the service keeps serving."""

import json

import pytest
import zmq

from fxis_shm.errors import Code

from .test_requests import assert_stamps_match

pytestmark = pytest.mark.integration

BAD_REQUESTS = [
    ("garbage bytes", [b"\xff\xfe\x00garbage"], Code.BAD_REQUEST),
    ("empty frame", [b""], Code.BAD_REQUEST),
    ("two frames", [b'{"v": 1, "op": "time"}', b"extra"], Code.BAD_REQUEST),
    ("bad JSON", [b'{"v": 1, "op": '], Code.BAD_REQUEST),
    ("JSON list", [b"[1, 2]"], Code.BAD_REQUEST),
    ("no version", [b'{"op": "time"}'], Code.BAD_REQUEST),
    ("future version", [b'{"v": 99, "op": "time"}'], Code.UNSUPPORTED_VERSION),
    ("unknown op", [b'{"v": 1, "op": "teleport"}'], Code.UNKNOWN_OP),
    ("unknown camera", [b'{"v": 1, "op": "image", "camera": "nope"}'], Code.UNKNOWN_CAMERA),
    ("unknown tuple camera", [b'{"v": 1, "op": "tuple", "cameras": ["cam0", "x"]}'], Code.UNKNOWN_CAMERA),
    ("camera as number", [b'{"v": 1, "op": "image", "camera": 3}'], Code.BAD_REQUEST),
    ("at as string", [b'{"v": 1, "op": "tuple", "at": "soon"}'], Code.BAD_REQUEST),
    ("negative timeout", [b'{"v": 1, "op": "tuple", "timeout_ms": -5}'], Code.BAD_REQUEST),
    ("bad sync", [b'{"v": 1, "op": "tuple", "sync": "psychic"}'], Code.BAD_REQUEST),
    ("unknown field", [b'{"v": 1, "op": "time", "color": "red"}'], Code.BAD_REQUEST),
    ("far future", [b'{"v": 1, "op": "tuple", "at": 9000000000000000000}'], Code.OUT_OF_RANGE),
    ("oversize header", [b'{"v": 1, "op": "time", "pad": "' + b"x" * 70000 + b'"}'], Code.TOO_LARGE),
]


@pytest.fixture
def raw(two_cameras):
    sock = zmq.Context.instance().socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.RCVTIMEO, 5000)
    sock.connect(two_cameras.endpoint)
    yield sock
    sock.close()


@pytest.mark.parametrize("frames,code", [(f, c) for _, f, c in BAD_REQUESTS], ids=[name for name, _, _ in BAD_REQUESTS])
def test_bad_request_gets_an_error_reply(raw, two_cameras, frames, code):
    raw.send_multipart([b""] + frames)
    reply = raw.recv_multipart()
    header = json.loads(reply[1])
    assert header["ok"] is False
    assert header["error"]["code"] == code
    assert header["error"]["message"]
    with two_cameras.client() as client:  # still serving
        assert_stamps_match(client.tuple())


def test_error_reply_echoes_a_readable_id(raw):
    raw.send_multipart([b"", b'{"v": 1, "op": "nope", "id": 42}'])
    header = json.loads(raw.recv_multipart()[1])
    assert header["id"] == 42 and header["error"]["code"] == Code.UNKNOWN_OP


def test_dealer_without_delimiter_is_answered(raw):
    raw.send_multipart([b'{"v": 1, "op": "time", "id": 7}'])
    reply = raw.recv_multipart()
    header = json.loads(reply[0])
    assert header["ok"] and header["id"] == 7


def test_a_message_over_1_mib_drops_that_connection_and_the_service_goes_on(two_cameras):
    """The service takes messages (each frame of one) of up to 1 MiB (MAX_MESSAGE_BYTES); ZeroMQ
    drops the connection of a peer that sends a larger one, before the service reads it
    (docs/protocol.md, 1). Just under the limit a request is read, and refused with a reply."""
    from fxis_shm.service.serversockets import MAX_MESSAGE_BYTES

    assert MAX_MESSAGE_BYTES == 1 << 20
    sock = zmq.Context.instance().socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    monitor = sock.get_monitor_socket(zmq.EVENT_CONNECTED | zmq.EVENT_DISCONNECTED)
    sock.connect(two_cameras.endpoint)
    try:
        assert next_event(monitor) == zmq.EVENT_CONNECTED

        def padded(request_id, size):
            head = b'{"v": 1, "op": "time", "id": %d, "pad": "' % request_id
            return head + b"x" * (size - len(head) - 2) + b'"}'

        sock.send_multipart([b"", padded(1, MAX_MESSAGE_BYTES - 1024)])  # under the limit: read, refused
        assert sock.poll(5000), "no reply to a request just under the limit"
        header = json.loads(sock.recv_multipart()[1])
        assert header["id"] == 1 and header["error"]["code"] == Code.TOO_LARGE
        assert "exceeds the limit" in header["error"]["message"]
        sock.send_multipart([b"", padded(2, MAX_MESSAGE_BYTES + 1024)])  # over it: the connection goes
        assert next_event(monitor) == zmq.EVENT_DISCONNECTED
        with two_cameras.client() as client:  # the others are served
            assert_stamps_match(client.tuple())
        assert next_event(monitor) == zmq.EVENT_CONNECTED  # ZeroMQ connects again by itself
        sock.send_multipart([b"", b'{"v": 1, "op": "time", "id": 3}'])
        assert sock.poll(5000), "no reply after the connection was made again"
        header = json.loads(sock.recv_multipart()[1])
        assert header["id"] == 3 and header["ok"] is True  # never an answer to id 2
    finally:
        sock.disable_monitor()
        monitor.close()
        sock.close()


def next_event(monitor, timeout_ms: int = 10_000) -> int:
    from zmq.utils.monitor import recv_monitor_message

    assert monitor.poll(timeout_ms), "no connection event"
    return int(recv_monitor_message(monitor)["event"])
