"""What the dashboard computes without I/O (fxis_shm.viewers.preview) and its config (http)."""

from __future__ import annotations

import numpy as np
import pytest

from fxis_shm.errors import ConfigError, InvalidArgument
from fxis_shm.service.config import build_config
from fxis_shm.viewers.preview import (
    EncodedCache,
    RateMeter,
    SkewHistory,
    displayable,
    frame_intervals_ms,
    parse_fps,
    parse_width,
    preview_jpeg,
    scaled,
)
from fxis_shm.wire import encoding


@pytest.mark.parametrize(
    "text, words",
    [("abc", "whole number"), ("0", "from 1"), ("-3", "from 1"), ("99999", "4096"), ("1.5", "whole number")],
)
def test_a_bad_width_is_refused_naming_it(text, words):
    with pytest.raises(InvalidArgument, match="width") as info:
        parse_width(text)
    assert words in str(info.value)


@pytest.mark.parametrize("text", ["-1", "0", "nan", "inf", "abc", "61"])
def test_a_bad_fps_is_refused_naming_it(text):
    with pytest.raises(InvalidArgument, match="fps"):
        parse_fps(text)


def test_parameters_not_given_take_their_defaults():
    assert parse_width(None) == 640 and parse_width("") == 640 and parse_width("200") == 200
    assert parse_fps(None) == 5.0 and parse_fps("2.5") == 2.5


def test_previews_are_scaled_down_never_up_keeping_the_aspect_ratio():
    image = np.zeros((1024, 1360), np.uint8)
    assert scaled(image, 680).shape == (512, 680)
    assert scaled(image, 5000) is image


@pytest.mark.parametrize(
    "image, shape",
    [
        (np.full((8, 10), 0x1234, np.uint16), (8, 10)),
        (np.zeros((8, 10, 4), np.uint8), (8, 10, 3)),
        (np.zeros((8, 10, 1), np.uint8), (8, 10)),
        (np.linspace(0, 1, 80, dtype=np.float32).reshape(8, 10), (8, 10)),
    ],
)
def test_every_stored_format_becomes_something_jpeg_takes(image, shape):
    shown = displayable(image)
    assert shown.dtype == np.uint8 and shown.shape == shape


def test_sixteen_bit_frames_keep_their_high_byte():
    assert displayable(np.full((2, 2), 0x1234, np.uint16))[0, 0] == 0x12


def test_a_preview_decodes_to_the_scaled_size():
    image = (np.arange(240 * 320) % 251).astype(np.uint8).reshape(240, 320)
    data = preview_jpeg(image, 160)
    assert encoding.decode(data, encoding.JPEG, (120, 160), "uint8").shape == (120, 160)


def test_the_cache_encodes_each_key_once_and_forgets_the_oldest():
    cache = EncodedCache(entries=2)
    calls = []

    def make(tag):
        return lambda: calls.append(tag) or tag.encode()

    assert cache.get("a", make("a")) == b"a"
    assert cache.get("a", make("x")) == b"a"  # cached: not made again
    cache.get("b", make("b"))
    cache.get("c", make("c"))  # "a" is the least recently used: out
    cache.get("a", make("a"))
    assert calls == ["a", "b", "c", "a"] and cache.encoded == 4
    cache.discard("a")
    cache.get("a", make("a"))
    assert cache.encoded == 5


def test_the_rate_is_measured_over_the_samples_and_restarts_with_the_counter():
    meter = RateMeter(window_s=10)
    assert meter.add(0, 100) is None
    assert meter.add(1_000_000_000, 120) == 20.0
    assert meter.add(2_000_000_000, 150) == 25.0
    assert meter.add(3_000_000_000, 5) is None  # a new generation counts from zero again
    assert meter.add(4_000_000_000, 15) == 10.0


def test_the_rate_forgets_samples_older_than_its_window():
    meter = RateMeter(window_s=2)
    for second, count in enumerate([0, 100, 110, 120, 130]):
        rate = meter.add(second * 1_000_000_000, count)
    assert rate == 10.0


def test_dropped_frames_show_as_a_spike_and_only_a_restart_breaks_the_series():
    columns = ["frame_id", "t_capture", "t_stored", "t_available", "generation"]
    rows = [[1, 0, 0, 0, 1], [2, 50_000_000, 0, 0, 1], [4, 150_000_000, 0, 0, 1], [5, 200_000_000, 0, 0, 1]]
    assert frame_intervals_ms(rows, columns, last=10) == [50.0, 100.0, 50.0]  # frame 3 dropped: a spike
    assert frame_intervals_ms(rows, columns, last=1) == [50.0]
    restarted = [*rows, [0, 900_000_000, 0, 0, 2], [1, 950_000_000, 0, 0, 2]]
    assert frame_intervals_ms(restarted, columns, last=10) == [50.0, 100.0, 50.0, 50.0]


def test_the_skew_history_keeps_the_newest():
    history = SkewHistory(length=2)
    for t, skew in [(1.0, 1_000_000), (2.0, 2_000_000), (3.0, 500_000)]:
        history.add(t, skew)
    assert history.points(3.5) == [(-1.5, 2.0), (-0.5, 0.5)]  # seconds before "now", as the page draws them


# ---- the http setting ----


def test_the_dashboard_is_on_loopback_by_default_and_can_be_turned_off():
    assert build_config().http == "127.0.0.1:8080"
    assert build_config().http_url == "http://127.0.0.1:8080"
    assert build_config({"http": "off"}).http_url is None
    assert build_config({}, {"http": "off"}).http_url is None
    assert build_config({"http": "[::1]:9000"}).exposed == []


@pytest.mark.parametrize("value", ["8080", "localhost:", "host:99999", ":80", "a:b"])
def test_a_bad_http_address_names_the_setting(value):
    with pytest.raises(ConfigError, match="http"):
        build_config({"http": value})


def test_a_dashboard_for_other_hosts_requires_a_token_unless_insecure_bind():
    config = build_config({}, {"http": "0.0.0.0:8080"})
    assert config.token_viewers == ["http"] and config.exposed_unencrypted == []
    config = build_config({}, {"http": "0.0.0.0:8080", "insecure_bind": True})
    assert config.token_viewers == [] and config.exposed_unencrypted == ["http://0.0.0.0:8080"]
