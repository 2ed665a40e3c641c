"""Service configuration and typed camera options (fxis_shm.service.config, fxis_shm.service.options)."""

from __future__ import annotations

import pytest

from fxis_shm.errors import ConfigError
from fxis_shm.service.config import build_config, load_toml, parse_camera_flag
from fxis_shm.service.options import Option, boolean, choice, number, parse_options, split_key_values, text

SYNTHETIC_DEFAULTS = {
    "fps": 20.0,
    "width": 1360,
    "height": 1024,
    "pixel_format": "mono8",
    "exposure_us": 10_000.0,
    "gain": 0.0,
    "phase_ms": 0.0,
    "jitter_ms": 0.0,
    "drop": 0.0,
    "buffers": 12,
    "seed": 0,
    "pattern": "stripes",
    "shift_px": 0,
    "trigger": "free",
    "trigger_latency_ms": 0.0,
    "process": None,
    "process_workers": 1,  # generic to every kind (camerakinds.COMMON_OPTIONS)
    "history": None,
    "frame_id": None,
    "calibration": None,
    "capture_tolerance_ms": 2.0,
}


def cameras_of(config) -> dict[str, dict]:
    return {spec.name: spec.options for spec in config.cameras}


def config_error(file_values=None, flags=None) -> str:
    with pytest.raises(ConfigError) as info:
        build_config(file_values, flags)
    return str(info.value)


# ---- defaults ----


def test_defaults_are_two_synthetic_cameras_and_local_endpoints():
    config = build_config()
    assert [(c.name, c.kind) for c in config.cameras] == [("cam0", "synthetic"), ("cam1", "synthetic")]
    assert cameras_of(config) == {"cam0": SYNTHETIC_DEFAULTS, "cam1": SYNTHETIC_DEFAULTS}
    assert config.slots == 20
    assert config.endpoint == "tcp://127.0.0.1:5555"
    assert config.pub == "tcp://127.0.0.1:5556"
    assert config.name == "fxis"
    assert config.settings == {}


def test_option_defaults_have_their_declared_types():
    options = cameras_of(build_config())["cam0"]
    assert type(options["fps"]) is float
    assert type(options["width"]) is int and type(options["height"]) is int
    assert type(options["seed"]) is int


@pytest.mark.parametrize(
    "flags",
    [None, {}, {"name": None, "endpoint": None, "pub": None, "slots": None, "cameras": []}, {"cameras": ()}],
)
def test_flags_that_were_not_given_change_nothing(flags):
    assert build_config({}, flags) == build_config()


# ---- --camera flags ----


@pytest.mark.parametrize(
    "flag, name, options",
    [
        ("left=synthetic", "left", {}),
        ("left=synthetic:", "left", {}),
        ("left=synthetic:fps=30", "left", {"fps": 30.0}),
        (
            "cam-2=synthetic:fps=7.5,width=640,height=480,pixel_format=bgr8",
            "cam-2",
            {"fps": 7.5, "width": 640, "height": 480, "pixel_format": "bgr8"},
        ),
        (
            "r_1=synthetic:phase_ms=-12.5,jitter_ms=0.25,drop=0.1,seed=42",
            "r_1",
            {"phase_ms": -12.5, "jitter_ms": 0.25, "drop": 0.1, "seed": 42},
        ),
        (" left = synthetic : fps = 30 , width = 64 ,", "left", {"fps": 30.0, "width": 64}),
        ("left=synthetic:fps=1e2", "left", {"fps": 100.0}),
        ("right=synthetic:pattern=chessboard,shift_px=-24", "right", {"pattern": "chessboard", "shift_px": -24}),
    ],
)
def test_a_camera_flag_gives_typed_options(flag, name, options):
    spec = parse_camera_flag(flag)
    assert (spec.name, spec.kind) == (name, "synthetic")
    assert spec.options == {**SYNTHETIC_DEFAULTS, **options}
    for key, value in options.items():
        assert type(spec.options[key]) is type(value)


def test_camera_flags_replace_the_default_cameras():
    config = build_config(flags={"cameras": ["left=synthetic:fps=30", "right=synthetic"]})
    assert list(cameras_of(config)) == ["left", "right"]
    assert cameras_of(config)["left"]["fps"] == 30.0


# ---- the TOML file ----

FILE_VALUES = {
    "name": "lab",
    "endpoint": "ipc:///tmp/fxis-lab.sock",
    "pub": "tcp://0.0.0.0:7001",
    "insecure_bind": True,  # 0.0.0.0 is reachable from other hosts
    "slots": 64,
    "restart_limit": 0,
    "log_level": "debug",
    "sync": "independent",
    "wait": "next",
    "timeout_ms": 250,
    "max_skew_ms": 2.5,
    "max_pending": 16,
    "cameras": {
        "left": {"kind": "synthetic", "fps": 30, "width": 640, "height": 480},
        "right": {"kind": "synthetic", "fps": 30.0, "phase_ms": 5, "pixel_format": "bgr8"},
    },
}


def test_file_values_are_typed_and_checked():
    config = build_config(FILE_VALUES)
    assert (config.name, config.endpoint, config.pub) == ("lab", "ipc:///tmp/fxis-lab.sock", "tcp://0.0.0.0:7001")
    assert (config.slots, config.restart_limit, config.log_level) == (64, 0, "DEBUG")
    assert config.settings == {
        "sync": "independent",
        "wait": "next",
        "timeout_ms": 250.0,
        "max_skew_ms": 2.5,
        "max_pending": 16,
    }
    assert type(config.settings["timeout_ms"]) is float
    assert cameras_of(config) == {
        "left": {**SYNTHETIC_DEFAULTS, "fps": 30.0, "width": 640, "height": 480},
        "right": {**SYNTHETIC_DEFAULTS, "fps": 30.0, "phase_ms": 5.0, "pixel_format": "bgr8"},
    }


def test_build_config_does_not_modify_the_values_it_is_given():
    values = {"slots": 8, "cameras": {"left": {"kind": "synthetic", "fps": 30}}}
    build_config(values)
    assert values == {"slots": 8, "cameras": {"left": {"kind": "synthetic", "fps": 30}}}


def test_a_real_toml_file_loads(tmp_path):
    path = tmp_path / "fxis.toml"
    path.write_text(
        'name = "bench"\n'
        "slots = 40\n"
        'sync = "joint"\n'
        "\n"
        "[cameras.front]\n"
        'kind = "synthetic"\n'
        "fps = 60\n"
        'pixel_format = "bgr8"\n'
        "\n"
        "[cameras.back]\n"
        'kind = "synthetic"\n'
        "phase_ms = 8.3\n"
    )
    config = build_config(load_toml(str(path)))
    assert (config.name, config.slots, config.settings) == ("bench", 40, {"sync": "joint"})
    assert cameras_of(config) == {
        "front": {**SYNTHETIC_DEFAULTS, "fps": 60.0, "pixel_format": "bgr8"},
        "back": {**SYNTHETIC_DEFAULTS, "phase_ms": 8.3},
    }


def test_flags_override_the_file():
    config = build_config(
        FILE_VALUES,
        {
            "name": "override",
            "slots": 8,
            "endpoint": "tcp://127.0.0.1:9000",
            "cameras": ["left=synthetic:fps=5", "extra=synthetic"],
        },
    )
    assert (config.name, config.slots, config.endpoint) == ("override", 8, "tcp://127.0.0.1:9000")
    assert config.pub == FILE_VALUES["pub"]  # not overridden
    options = cameras_of(config)
    assert list(options) == ["left", "right", "extra"]
    # a flag replaces the whole camera: its file options do not carry over
    assert options["left"] == {**SYNTHETIC_DEFAULTS, "fps": 5.0}
    assert options["right"]["pixel_format"] == "bgr8"


# ---- bad settings: each ConfigError names what is wrong ----


@pytest.mark.parametrize(
    "flag, named",
    [
        ("cam0=nosuchkind", "nosuchkind"),
        ("cam0=", "''"),
        ("cam0=synthetic:colour=red", "colour"),
        ("cam0=synthetic:fps=0", "'fps'"),
        ("cam0=synthetic:fps=-5", "'fps'"),
        ("cam0=synthetic:fps=abc", "'fps'"),
        ("cam0=synthetic:fps=nan", "'fps'"),
        ("cam0=synthetic:fps=inf", "'fps'"),
        ("cam0=synthetic:fps=20000", "'fps'"),
        ("cam0=synthetic:drop=2", "'drop'"),
        ("cam0=synthetic:drop=-0.1", "'drop'"),
        ("cam0=synthetic:width=8", "'width'"),
        ("cam0=synthetic:width=64.5", "'width'"),
        ("cam0=synthetic:height=0", "'height'"),
        ("cam0=synthetic:seed=-1", "'seed'"),
        ("cam0=synthetic:jitter_ms=-1", "'jitter_ms'"),
        ("cam0=synthetic:pixel_format=rgb", "'pixel_format'"),
        ("cam0=synthetic:pixel_format=", "'pixel_format'"),
        ("bad name=synthetic", "camera name"),
        ("cam/0=synthetic", "camera name"),
        ("c" * 49 + "=synthetic", "camera name"),
        ("cam0", "--camera"),
        ("=synthetic", "--camera"),
        ("cam0=synthetic:fps", "key=value"),
        ("cam0=synthetic:=30", "key=value"),
    ],
)
def test_a_bad_camera_flag_names_the_problem(flag, named):
    with pytest.raises(ConfigError) as info:
        parse_camera_flag(flag)
    assert named in str(info.value)


def test_build_config_rejects_a_bad_camera_flag_among_good_ones():
    message = config_error(flags={"cameras": ["left=synthetic", "right=synthetic:fps=0"]})
    assert "'right'" in message and "'fps'" in message


@pytest.mark.parametrize(
    "file_values, named",
    [
        ({"cameras": {"cam0": {"kind": "nosuchkind"}}}, "nosuchkind"),
        ({"cameras": {"cam0": {"kind": "synthetic", "fps": 0}}}, "'fps'"),
        ({"cameras": {"cam0": {"kind": "synthetic", "fps": "abc"}}}, "'fps'"),
        ({"cameras": {"cam0": {"kind": "synthetic", "fps": True}}}, "'fps'"),
        ({"cameras": {"cam0": {"kind": "synthetic", "width": 64.5}}}, "'width'"),
        ({"cameras": {"cam0": {"kind": "synthetic", "drop": 2}}}, "'drop'"),
        ({"cameras": {"cam0": {"kind": "synthetic", "pixel_format": "rgb"}}}, "'pixel_format'"),
        ({"cameras": {"cam0": {"kind": "synthetic", "pattern": "checkers"}}}, "'pattern'"),
        ({"cameras": {"cam0": {"kind": "synthetic", "shift_px": 2.5}}}, "'shift_px'"),
        ({"cameras": {"cam0": {"kind": "synthetic", "shutter": 1}}}, "shutter"),
        ({"cameras": {"cam0": {"fps": 20}}}, "[cameras.cam0]"),
        ({"cameras": {"cam0": "synthetic"}}, "[cameras.cam0]"),
        ({"cameras": {"bad name": {"kind": "synthetic"}}}, "camera name"),
        ({"cameras": ["cam0"]}, "cameras"),
        ({"name": "my service"}, "service name"),
        ({"name": ""}, "service name"),
        ({"name": 5}, "service name"),
        ({"slots": 1}, "slots"),
        ({"slots": 0}, "slots"),
        ({"slots": 2.5}, "slots"),
        ({"slots": "20"}, "slots"),
        ({"slots": True}, "slots"),
        ({"restart_limit": -1}, "restart_limit"),
        ({"endpoint": "http://127.0.0.1:5555"}, "endpoint"),
        ({"endpoint": "127.0.0.1:5555"}, "endpoint"),
        ({"endpoint": 5555}, "endpoint"),
        ({"pub": "udp://127.0.0.1:5556"}, "pub"),
        ({"endpoint": "tcp://127.0.0.1:5556"}, "endpoint, pub and events"),
        ({"pub": "tcp://127.0.0.1:5555"}, "endpoint, pub and events"),
        ({"log_level": "chatty"}, "log_level"),
        ({"sync": "best"}, "sync"),
        ({"wait": "always"}, "wait"),
        ({"timeout_ms": 0}, "timeout_ms"),
        ({"timeout_ms": -1}, "timeout_ms"),
        ({"timeout_ms": "abc"}, "timeout_ms"),
        ({"timeout_ms": True}, "timeout_ms"),
        ({"timeout_ms": float("nan")}, "timeout_ms"),
        ({"timeout_ms": float("inf")}, "timeout_ms"),
        ({"horizon_ms": float("inf")}, "horizon_ms"),
        ({"max_pending": 0}, "max_pending"),
        ({"max_pending": float("inf")}, "max_pending"),
        ({"horizon_ms": None}, "horizon_ms"),
        ({"colour": "red"}, "colour"),
        ({"camera": {}}, "'camera'"),
    ],
)
def test_a_bad_file_setting_names_the_problem(file_values, named):
    assert named in config_error(file_values)


@pytest.mark.parametrize(
    "flags, named",
    [
        ({"slots": 1}, "slots"),
        ({"name": "a.b"}, "service name"),
        ({"endpoint": "inproc://x"}, "endpoint"),
        ({"pub": "tcp://127.0.0.1:5555"}, "endpoint, pub and events"),
        ({"log_level": "loud"}, "log_level"),
    ],
)
def test_a_bad_flag_names_the_problem(flags, named):
    assert named in config_error({}, flags)


@pytest.mark.parametrize(
    "content",
    ["slots = \n", "[cameras.left\nkind = 'synthetic'\n", "name = 'a'\nname = 'b'\n", "= 3\n"],
)
def test_an_invalid_toml_file_names_the_file(tmp_path, content):
    path = tmp_path / "bad.toml"
    path.write_text(content)
    with pytest.raises(ConfigError, match="not valid TOML") as info:
        load_toml(str(path))
    assert str(path) in str(info.value) and "--config" in str(info.value)


@pytest.mark.parametrize("name", ["missing.toml", "."])
def test_an_unreadable_config_file_names_the_file(tmp_path, name):
    path = tmp_path / name
    with pytest.raises(ConfigError, match="--config") as info:
        load_toml(str(path))
    assert str(path) in str(info.value)


# ---- options.py building blocks ----


@pytest.mark.parametrize(
    "text_, expected",
    [
        ("", {}),
        ("a=1", {"a": "1"}),
        ("a=1,b=2", {"a": "1", "b": "2"}),
        (" a = 1 ,, b=2 ,", {"a": "1", "b": "2"}),
        ("a=", {"a": ""}),
        ("path=x=y", {"path": "x=y"}),
        ("a=1,a=2", {"a": "2"}),  # the last one wins
    ],
)
def test_split_key_values(text_, expected):
    assert split_key_values("cam", text_) == expected


@pytest.mark.parametrize("text_", ["a", "a=1,b", "=1", " =1"])
def test_split_key_values_rejects_items_without_a_key(text_):
    with pytest.raises(ConfigError, match="'cam'.*key=value"):
        split_key_values("cam", text_)


SCHEMA = {
    "rate": Option(number(float, 0, exclusive_min=True), 1.0, "a positive number"),
    "count": Option(number(int, 0, 10), 3, "an integer from 0 to 10"),
    "mode": Option(choice("a", "b"), "a", "a or b"),
    "flag": Option(boolean, False, "a boolean"),
    "label": Option(text, "", "text"),
}


def test_parse_options_fills_defaults_and_types_values():
    parsed = parse_options("cam", "kind", SCHEMA, {"rate": "2.5", "count": "10", "flag": "yes", "label": 7})
    assert parsed == {"rate": 2.5, "count": 10, "mode": "a", "flag": True, "label": "7"}


def test_parse_options_lists_unknown_and_known_keys():
    with pytest.raises(ConfigError) as info:
        parse_options("cam", "kind", SCHEMA, {"zoom": 1, "focus": 2})
    message = str(info.value)
    assert "focus, zoom" in message
    assert "count, flag, label, mode, rate" in message
    assert "'cam'" in message and "'kind'" in message


@pytest.mark.parametrize(
    "raw",
    [
        {"rate": 0},
        {"rate": "x"},
        {"count": 11},
        {"count": -1},
        {"count": 2.5},
        {"count": True},
        {"mode": "c"},
        {"flag": "maybe"},
        {"flag": 2},
        {"label": None},
        {"label": 1.5},
    ],
)
def test_parse_options_names_the_key_of_a_bad_value(raw):
    (key,) = raw
    with pytest.raises(ConfigError, match=f"camera 'cam': key '{key}'"):
        parse_options("cam", "kind", SCHEMA, raw)


@pytest.mark.parametrize(
    "value, expected",
    [
        (True, True),
        (False, False),
        ("1", True),
        ("TRUE", True),
        (" on ", True),
        ("yes", True),
        ("0", False),
        ("False", False),
        ("off", False),
        ("no", False),
        (1, True),
        (0, False),
    ],
)
def test_boolean_accepts_the_usual_spellings(value, expected):
    assert boolean(value) is expected


def test_an_exposed_endpoint_needs_curve_keys_or_insecure_bind():
    with pytest.raises(ConfigError, match="other hosts"):
        build_config({"pub": "tcp://0.0.0.0:7001"})
    assert build_config({"pub": "tcp://0.0.0.0:7001", "insecure_bind": True}).exposed == ["tcp://0.0.0.0:7001"]
    with pytest.raises(ConfigError, match="go together"):
        build_config({"curve_secret": "server.key_secret"})


def test_lockstep_is_a_rate_and_a_phase_from_the_flag_or_the_file():
    assert build_config(flags={"lockstep": "20,5"}).lockstep == (20.0, 5_000_000)
    assert build_config({"lockstep": 30}).lockstep == (30.0, 0)
    assert build_config().lockstep is None
    with pytest.raises(ConfigError, match="above 0"):
        build_config(flags={"lockstep": "0"})


def test_the_lockstep_grids_clock_is_realtime_or_tai_from_the_flag_or_the_file():
    assert build_config().lockstep_clock == "realtime"
    assert build_config({"lockstep_clock": "tai"}).lockstep_clock == "tai"
    assert build_config({"lockstep_clock": "tai"}, flags={"lockstep_clock": "realtime"}).lockstep_clock == "realtime"
    with pytest.raises(ConfigError, match="realtime or tai"):
        build_config({"lockstep_clock": "monotonic"})
