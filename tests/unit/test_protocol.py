"""The wire codec (fxis_shm.wire.protocol): round trips and every kind of malformed message."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fxis_shm.core.snapshot import SlotMeta
from fxis_shm.errors import Code, ProtocolError
from fxis_shm.wire.framemeta import frame_meta, frame_ref, ring_place
from fxis_shm.wire.protocol import (
    CLOCK,
    MAX_HEADER_BYTES,
    VERSION,
    decode_event,
    decode_reply,
    decode_request,
    encode_error,
    encode_event,
    encode_reply,
    encode_request,
)


def raw(header) -> list[bytes]:
    """A request or reply of one JSON header frame, whatever ``header`` is."""
    return [json.dumps(header).encode()]


def request(**fields) -> list[bytes]:
    return raw({"v": VERSION, **fields})


def rejected(frames, code=Code.BAD_REQUEST) -> str:
    """Decode a request that must fail with ``code``; return the error message."""
    with pytest.raises(ProtocolError) as info:
        decode_request(frames)
    assert info.value.code == code
    assert info.value.message == str(info.value)
    return info.value.message


# ---- requests: round trips ----

ENCODED = {"encoding": "raw", "quality": None}
REQUEST_DEFAULTS = {
    "image": {
        "id": None,
        "camera": ...,
        "at": None,
        "t_call": None,
        "wait": None,
        "timeout_ms": None,
        "capture": None,
        "local": None,
        **ENCODED,
    },
    "tuple": {
        "id": None,
        "cameras": None,
        "sync": None,
        "max_skew_ms": None,
        "partial": None,
        "at": None,
        "t_call": None,
        "wait": None,
        "timeout_ms": None,
        "capture": None,
        "local": None,
        **ENCODED,
    },
    "latest": {"id": None, "cameras": None, "local": None, **ENCODED},
    "status": {"id": None},
    "time": {"id": None},
}


@pytest.mark.parametrize(
    "op, fields",
    [
        ("image", {"camera": "cam0"}),
        ("image", {"camera": "cam0", "id": 7, "at": 123_456_789_012, "wait": "next", "timeout_ms": 250.5}),
        ("image", {"camera": "left", "at": -5, "wait": "none", "timeout_ms": 1}),
        ("tuple", {}),
        ("tuple", {"cameras": ["a", "b"], "sync": "independent", "max_skew_ms": 2, "wait": "auto", "id": "req-1"}),
        ("tuple", {"cameras": ["a"], "sync": "joint", "max_skew_ms": 0.5, "at": 0}),
        ("latest", {}),
        ("latest", {"cameras": ["cam1"]}),
        ("tuple", {"local": "0b1e6f3c-5a4f-4d1e-9c1b-2f3e4d5c6b7a"}),
        ("status", {"id": 0}),
        ("time", {"id": ""}),
    ],
)
def test_a_request_round_trips_with_its_defaults_filled_in(op, fields):
    decoded = decode_request(encode_request(op, **fields))
    expected = {"v": VERSION, "op": op, **REQUEST_DEFAULTS[op], **fields}
    assert decoded == expected
    assert ... not in decoded.values()  # every required field was given


def test_encode_request_leaves_out_fields_that_are_none():
    (frame,) = encode_request("image", camera="cam0", at=None, wait=None)
    assert json.loads(frame) == {"v": VERSION, "op": "image", "camera": "cam0"}


def test_explicit_nulls_mean_the_defaults():
    assert decode_request(request(op="image", camera="c", at=None, id=None))["at"] is None


def test_a_header_at_the_size_limit_is_accepted():
    frames = encode_request("status", id="x")
    padding = MAX_HEADER_BYTES - len(frames[0])
    frames = encode_request("status", id="x" * (1 + padding))
    assert len(frames[0]) == MAX_HEADER_BYTES
    assert decode_request(frames)["op"] == "status"


@pytest.mark.parametrize("as_type", [bytes, bytearray, memoryview])
def test_a_request_frame_may_be_any_bytes_like_object(as_type):
    (frame,) = encode_request("time", id=1)
    assert decode_request([as_type(frame)])["id"] == 1


# ---- requests: malformed messages ----


@pytest.mark.parametrize("frames", [[], request(op="time") * 2, [b'{"v": 1}', b""]])
def test_a_request_is_exactly_one_frame(frames):
    assert "one frame" in rejected(frames)


@pytest.mark.parametrize(
    "frame",
    [
        b"\xc3\x28\xff\xfe",  # not UTF-8
        b"\xff\xfe\x00",  # a UTF-16 byte order mark, then a truncated character
        b"",
        b"{",
        b'{"v": 1, "op": "time"',
        b"{'v': 1}",  # Python, not JSON
        b'{"v": 1, "op": "time"} trailing',
        b"not json at all",
    ],
)
def test_a_header_that_is_not_json_is_a_bad_request(frame):
    assert "not valid JSON" in rejected([frame])


@pytest.mark.parametrize("header", [[1, 2], [], 42, 1.5, "time", None, True])
def test_a_header_must_be_a_json_object(header):
    assert "JSON object" in rejected(raw(header))


def test_a_header_needs_a_version():
    assert "'v'" in rejected(raw({"op": "time"}))


@pytest.mark.parametrize("version", [0, 2, 99, -1, "1", [1], None])
def test_other_protocol_versions_are_unsupported(version):
    message = rejected(raw({"v": version, "op": "time"}), Code.UNSUPPORTED_VERSION)
    assert str(VERSION) in message


@pytest.mark.parametrize("version", [True, 1.0])
def test_a_version_equal_to_1_but_not_the_integer_1_is_a_bad_request(version):
    assert "'v'" in rejected(raw({"v": version, "op": "time"}))


@pytest.mark.parametrize("op", [None, 3, "", ["time"], {"name": "time"}])
def test_op_must_be_a_non_empty_string(op):
    header = {"v": VERSION} if op is None else {"v": VERSION, "op": op}
    assert "'op'" in rejected(raw(header))


@pytest.mark.parametrize("op", ["grab", "IMAGE", "images", "__init__"])
def test_an_unknown_op_has_its_own_code(op):
    assert repr(op) in rejected(request(op=op), Code.UNKNOWN_OP)


@pytest.mark.parametrize(
    "header, field",
    [
        ({"op": "time", "camera": "cam0"}, "camera"),  # a field of another op
        ({"op": "image", "camera": "cam0", "cameras": ["cam0"]}, "cameras"),
        ({"op": "latest", "at": 5}, "at"),
        ({"op": "status", "verbose": True}, "verbose"),
        ({"op": "tuple", "timeout": 100}, "timeout"),
    ],
)
def test_unknown_fields_are_rejected_by_name(header, field):
    assert repr(field) in rejected(request(**header))


def test_a_required_field_must_be_given():
    assert "'camera'" in rejected(request(op="image", at=5))


@pytest.mark.parametrize(
    "op, field, value",
    [
        ("image", "camera", 3),
        ("image", "camera", ""),
        ("image", "camera", ["cam0"]),
        ("image", "camera", None),  # required, so null is not "absent"
        ("tuple", "cameras", "cam0"),
        ("tuple", "cameras", []),
        ("tuple", "cameras", {"cam0": 1}),
        ("tuple", "cameras", ["cam0", "cam0"]),
        ("tuple", "cameras", ["cam0", 1]),
        ("tuple", "cameras", ["cam0", ""]),
        ("latest", "cameras", ["a", "b", "a"]),
        ("image", "at", 1.5),
        ("image", "at", 1e18),
        ("image", "at", True),
        ("image", "at", "123"),
        ("tuple", "at", [1]),
        ("image", "timeout_ms", -1),
        ("image", "timeout_ms", 0),
        ("image", "timeout_ms", 0.0),
        ("image", "timeout_ms", "NaN"),
        ("image", "timeout_ms", "100"),
        ("image", "timeout_ms", True),
        ("tuple", "sync", "best"),
        ("tuple", "sync", "JOINT"),
        ("tuple", "sync", 1),
        ("image", "wait", "always"),
        ("image", "wait", True),
        ("tuple", "wait", ["next"]),
        ("tuple", "max_skew_ms", -0.5),
        ("tuple", "max_skew_ms", 0),
        ("tuple", "max_skew_ms", "1"),
        ("time", "id", True),
        ("time", "id", [1]),
        ("time", "id", {"n": 1}),
        ("status", "id", 1.5),
    ],
)
def test_a_field_of_the_wrong_type_or_value_is_rejected_by_name(op, field, value):
    header = {"op": op, field: value}
    if op == "image" and field != "camera":
        header["camera"] = "cam0"
    assert repr(field) in rejected(request(**header))


@pytest.mark.parametrize("literal", [b"NaN", b"Infinity", b"-Infinity"])
@pytest.mark.parametrize("field", ["timeout_ms", "max_skew_ms"])
def test_non_finite_numbers_are_rejected(field, literal):
    # Python's json module accepts these non-standard literals; the codec must not
    frame = b'{"v": 1, "op": "tuple", "%s": %s}' % (field.encode(), literal)
    assert repr(field) in rejected([frame])


@pytest.mark.parametrize("limit", [MAX_HEADER_BYTES, 100])
def test_an_oversize_header_is_too_large(limit):
    frame = json.dumps({"v": VERSION, "op": "status", "id": "x" * limit}).encode()
    assert len(frame) > limit
    with pytest.raises(ProtocolError) as info:
        decode_request([frame], max_header_bytes=limit)
    assert info.value.code == Code.TOO_LARGE


def test_the_size_limit_applies_before_parsing():
    garbage = b"\xff" * (MAX_HEADER_BYTES + 1)
    rejected([garbage], Code.TOO_LARGE)


# ---- replies ----


def image(shape, dtype) -> np.ndarray:
    return (np.arange(int(np.prod(shape)), dtype=np.uint64) % 251).astype(dtype).reshape(shape)


def reply_of(images, request_id=5, order=None, **body) -> list:
    """A success reply carrying ``images``; buffer k holds images[order[k]]."""
    order = list(range(len(images))) if order is None else order
    metas = [
        frame_meta(
            f"cam{k}",
            frame_id=100 + k,
            t_capture=10**12 + k,
            t_stored=10**12 + 7,
            generation=2,
            image=img,
            buffer=order.index(k),
        )
        for k, img in enumerate(images)
    ]
    return encode_reply(request_id, {"frames": metas, **body}, [images[k] for k in order])


def over_the_wire(frames) -> list[bytes]:
    """What a receiver holds: each frame's bytes, copied."""
    return [bytes(memoryview(f)) for f in frames]


SHAPES = [
    ((4, 20), "uint8"),
    ((4, 20, 3), "uint8"),
    ((3, 17), "uint16"),
    ((2, 5), "float32"),
    ((1, 1), "uint8"),
    ((0, 8), "uint16"),
]


@pytest.mark.parametrize("shape, dtype", SHAPES)
@pytest.mark.parametrize("transport", [list, over_the_wire])
def test_a_reply_round_trips_images_of_every_layout(shape, dtype, transport):
    sent = image(shape, dtype)
    header, (received,) = decode_reply(transport(reply_of([sent])))
    assert received.shape == shape
    assert received.dtype == np.dtype(dtype)
    np.testing.assert_array_equal(received, sent)
    assert header["ok"] is True
    assert header["clock"] == CLOCK
    assert header["id"] == 5
    assert header["frames"][0] == {
        "camera": "cam0",
        "frame_id": 100,
        "t_capture": 10**12,
        "t_available": 10**12,
        "t_stored": 10**12 + 7,
        "generation": 2,
        "capture": "free",
        "t_target": None,
        "shape": list(shape),
        "dtype": dtype,
        "buffer": 0,
    }


def test_a_reply_maps_each_frame_to_the_buffer_it_names():
    sent = [image((2, 16), "uint8"), image((3, 16, 3), "uint8"), image((4, 4), "uint16")]
    header, received = decode_reply(over_the_wire(reply_of(sent, order=[2, 0, 1])))
    assert [m["buffer"] for m in header["frames"]] == [1, 2, 0]
    for got, want in zip(received, sent):
        np.testing.assert_array_equal(got, want)


def test_decoded_images_are_views_of_the_received_buffers():
    frames = [bytearray(f) for f in over_the_wire(reply_of([image((4, 20), "uint8")]))]
    _, (received,) = decode_reply(frames)
    frames[1][0] = 255
    assert received[0, 0] == 255


def test_frame_meta_converts_numpy_integers_for_json():
    meta = frame_meta("c", np.int64(3), np.int64(4), np.uint64(5), np.int32(1), image((2, 2), "uint8"), 0)
    assert json.loads(json.dumps(meta))["frame_id"] == 3
    assert all(type(meta[k]) is int for k in ("frame_id", "t_capture", "t_stored", "generation"))


def test_a_reply_body_is_passed_through():
    header, images = decode_reply(encode_reply("r", {"op": "time", "now": 12345}))
    assert images == []
    assert (header["id"], header["op"], header["now"]) == ("r", "time", 12345)


def test_an_error_reply_round_trips():
    header, images = decode_reply(encode_error(9, Code.UNKNOWN_CAMERA, "no camera 'x'"))
    assert images == []
    assert header["ok"] is False
    assert header["id"] == 9
    assert header["error"] == {"code": Code.UNKNOWN_CAMERA, "message": "no camera 'x'"}


# ---- replies: malformed ----


def reply_with_meta(meta, buffers) -> list:
    return raw({"v": VERSION, "ok": True, "frames": [meta]}) + list(buffers)


GOOD_META = {"buffer": 0, "dtype": "uint8", "shape": [2, 8]}


def bad_reply(reason) -> str:
    with pytest.raises(ProtocolError) as info:
        decode_reply(reason)
    return info.value.message


@pytest.mark.parametrize(
    "frames, expected",
    [
        ([], "empty"),
        ([b"\xff\xfe\xfd"], "not valid JSON"),
        ([b"{nope"], "not valid JSON"),
        (raw([1, 2]), "version-1 reply"),
        (raw({"v": 2, "ok": True}), "version-1 reply"),
        (raw({"v": VERSION}), "version-1 reply"),  # no "ok"
        (raw({"ok": True}), "version-1 reply"),
    ],
)
def test_a_reply_header_that_is_not_a_version_1_reply_is_rejected(frames, expected):
    assert expected in bad_reply(frames)


@pytest.mark.parametrize(
    "meta, buffers, expected",
    [
        (GOOD_META, [b"x" * 15], "buffer of 15 bytes"),  # one byte short
        (GOOD_META, [b"x" * 17], "buffer of 17 bytes"),  # one byte too many
        ({**GOOD_META, "dtype": "uint16"}, [b"x" * 16], "buffer of 16 bytes"),
        ({**GOOD_META, "shape": [2, 8, 3]}, [b"x" * 16], "buffer of 16 bytes"),
        (GOOD_META, [], "does not match"),  # no buffer at all
        ({**GOOD_META, "buffer": 1}, [b"x" * 16], "does not match"),
        ({**GOOD_META, "buffer": -1}, [b"x" * 16], "does not match"),
        ({**GOOD_META, "buffer": "0"}, [b"x" * 16], "does not match"),
        ({**GOOD_META, "buffer": True}, [b"x" * 16, b"x" * 16], "does not match"),
        ({"dtype": "uint8", "shape": [2, 8]}, [b"x" * 16], "does not match"),
        ({"buffer": 0, "shape": [2, 8]}, [b"x" * 16], "does not match"),
        ({"buffer": 0, "dtype": "uint8"}, [b"x" * 16], "does not match"),
        ({**GOOD_META, "shape": 16}, [b"x" * 16], "does not match"),
        ({**GOOD_META, "shape": ["two", 8]}, [b"x" * 16], "does not match"),
        ({**GOOD_META, "shape": [-2, -8]}, [b"x" * 16], "does not match"),
        ({**GOOD_META, "shape": [2**32, 2**32]}, [b""], "buffer of 0 bytes"),
        ({**GOOD_META, "dtype": "int64"}, [b"x" * 128], "unsupported dtype"),
        ({**GOOD_META, "dtype": "object"}, [b"x" * 128], "unsupported dtype"),
        ({**GOOD_META, "dtype": "no-such-type"}, [b"x" * 16], "does not match"),
        ("not a mapping", [b"x" * 16], "does not match"),
    ],
)
def test_frame_metadata_that_does_not_match_the_buffers_is_rejected(meta, buffers, expected):
    assert expected in bad_reply(reply_with_meta(meta, buffers))


@pytest.mark.parametrize("frames_field", [5, {"buffer": 0}, None])
def test_the_frames_field_of_a_reply_must_be_a_list(frames_field):
    reply = raw({"v": VERSION, "ok": True, "frames": frames_field}) + [b"x" * 16]
    assert "frames" in bad_reply(reply)


def test_deeply_nested_json_is_a_bad_request():
    with pytest.raises(ProtocolError) as info:
        decode_request([b"[" * 10_000 + b"]" * 10_000])  # within the size limit
    assert info.value.code == Code.BAD_REQUEST and "nested" in info.value.message


# ---- the local fast path ----


@pytest.mark.parametrize("bad", ["", "x" * 65, 7, ["id"], True])
def test_a_bad_local_boot_id_is_refused(bad):
    with pytest.raises(ProtocolError, match="'local'.*boot id"):
        decode_request(encode_request("tuple", local=bad))


def test_request_events_cannot_ask_for_ring_references():
    with pytest.raises(ProtocolError, match=r"unknown field\(s\) \['local'\]"):
        decode_event(encode_event("tuple", "replies", local="boot"))


def test_a_local_reply_names_where_each_frame_is_and_carries_no_buffers():
    record = SlotMeta(frame_id=7, t_capture=10**12, t_stored=10**12 + 5, t_available=10**12, generation=1)
    place = ring_place("/fxis.svc.cam0.ring", instance=np.uint64(2**63 + 1), slot=3, seq=np.uint64(88))
    ref = frame_ref("cam0", record, (1024, 1360), "uint8", place)
    header, images = decode_reply(over_the_wire(encode_reply(4, {"frames": [ref], "delivery": "local"})))
    assert images == []
    assert header["frames"][0] == {
        "camera": "cam0",
        "frame_id": 7,
        "t_capture": 10**12,
        "t_available": 10**12,
        "t_stored": 10**12 + 5,
        "generation": 1,
        "capture": "free",
        "t_target": None,
        "shape": [1024, 1360],
        "dtype": "uint8",
        "ring": "/fxis.svc.cam0.ring",
        "instance": str(2**63 + 1),  # uint64 travels as a decimal string
        "slot": 3,
        "seq": 88,
    }
