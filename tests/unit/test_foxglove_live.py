"""What the Foxglove live view computes without I/O (fxis_shm.viewers.foxglove_live) and its settings."""

from __future__ import annotations

import numpy as np
import pytest

from fxis_shm.errors import ConfigError
from fxis_shm.service.config import build_config, check_foxglove_rate
from fxis_shm.viewers.foxglove_live import RATE_PARAMETER, RateParameter, raw_image, raw_pixels

from ..foxglove_decode import message_class


@pytest.mark.parametrize(
    "shape, dtype, encoding",
    [
        ((4, 6), np.uint8, "mono8"),
        ((4, 6, 1), np.uint8, "mono8"),
        ((4, 6, 3), np.uint8, "bgr8"),
        ((4, 6, 4), np.uint8, "bgra8"),
        ((4, 6), np.uint16, "mono16"),
    ],
)
def test_frames_go_as_they_are_where_foxglove_has_the_encoding(shape, dtype, encoding):
    image = np.arange(np.prod(shape), dtype=dtype).reshape(shape)
    pixels, got = raw_pixels(image)
    assert got == encoding and pixels.tobytes() == image.tobytes()


def test_16_bit_pixels_are_little_endian_and_other_types_made_displayable():
    big = np.array([[1, 256]], dtype=">u2")
    pixels, encoding = raw_pixels(big)
    assert encoding == "mono16" and pixels.tobytes() == b"\x01\x00\x00\x01"
    pixels, encoding = raw_pixels(np.array([[0.0, 0.5, 1.0]], dtype=np.float32))
    assert encoding == "mono8" and pixels.tolist() == [[0, 127, 255]]


def test_a_raw_image_carries_the_capture_time_and_the_camera():
    image = np.arange(45, dtype=np.uint8).reshape(3, 5, 3)
    message = raw_image("cam0", image, 12 * 10**9 + 345)
    schema = message.get_schema()
    decoded = message_class(schema.name, schema.data).FromString(message.encode())  # as sent
    assert (decoded.timestamp.seconds, decoded.timestamp.nanos) == (12, 345)
    assert (decoded.frame_id, decoded.width, decoded.height, decoded.encoding, decoded.step) == (
        "cam0",
        5,
        3,
        "bgr8",
        15,
    )
    assert decoded.data == image.tobytes()


def test_the_rate_setting():
    assert build_config().foxglove_url is None and build_config().foxglove_rate == 10.0
    config = build_config({"foxglove": "127.0.0.1:8765", "foxglove_rate": 2})
    assert config.foxglove_url == "ws://127.0.0.1:8765" and config.foxglove_rate == 2.0
    assert build_config({}, {"foxglove": "127.0.0.1:8765", "foxglove_rate": "2.5"}).foxglove_rate == 2.5
    for bad in (0, -1, 61, "abc", True, float("nan"), None, [1]):
        with pytest.raises(ConfigError, match="foxglove_rate must be"):
            check_foxglove_rate(bad)


def test_a_foxglove_server_for_other_hosts_requires_a_token_unless_insecure_bind():
    config = build_config({}, {"foxglove": "0.0.0.0:8765"})
    assert config.token_viewers == ["foxglove"] and config.exposed_unencrypted == []
    config = build_config({}, {"foxglove": "0.0.0.0:8765", "insecure_bind": True})
    assert config.token_viewers == [] and config.exposed_unencrypted == ["ws://0.0.0.0:8765"]


def test_the_app_sets_the_rate_and_a_bad_value_leaves_it():
    rate = RateParameter(10)
    assert [p.get_value() for p in rate.on_get_parameters(None, [RATE_PARAMETER])] == [10.0]
    assert rate.on_get_parameters(None, ["other"]) == []
    from foxglove import Parameter

    assert rate.on_set_parameters(None, [Parameter(RATE_PARAMETER, value=-3.0)])[0].get_value() == 10.0
    assert rate.on_set_parameters(None, [Parameter(RATE_PARAMETER, value=4.0)])[0].get_value() == 4.0
    assert rate.hz == 4.0
