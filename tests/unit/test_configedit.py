"""Writing settings back into a config file (fxis set --save): in place, comments kept."""

import pytest

from fxis_shm.errors import ConfigError, ProtocolError
from fxis_shm.service.config import tomllib
from fxis_shm.service.configedit import save_camera_values
from fxis_shm.wire import commands

TEXT = """name = "cell"   # the service

[cameras."left"]   # the left one
kind = "synthetic"
gain = 1.0  # set by hand

[cameras.right]
kind = "synthetic"
"""


def test_values_replace_their_lines_or_join_the_table_and_the_rest_stays(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text(TEXT)
    save_camera_values(str(path), "left", {"gain": 2.5, "exposure_us": 4000.0, "pixel_format": "bgr8", "loop": True})
    text = path.read_text()
    assert 'name = "cell"   # the service' in text and '[cameras."left"]   # the left one' in text
    lines = text.splitlines()
    assert lines[lines.index("gain = 2.5") + 1 : lines.index("gain = 2.5") + 4] == [
        "exposure_us = 4000.0",
        'pixel_format = "bgr8"',
        "loop = true",
    ]
    read = tomllib.loads(text)["cameras"]
    assert read["left"] == {
        "kind": "synthetic",
        "gain": 2.5,
        "exposure_us": 4000.0,
        "pixel_format": "bgr8",
        "loop": True,
    }
    assert read["right"] == {"kind": "synthetic"}


def test_a_camera_without_a_table_is_refused_and_the_file_untouched(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text(TEXT)
    with pytest.raises(ConfigError, match=r"has no \[cameras.centre\] table"):
        save_camera_values(str(path), "centre", {"gain": 1.0})
    assert path.read_text() == TEXT
    with pytest.raises(ConfigError, match="cannot read"):
        save_camera_values(str(tmp_path / "none.toml"), "left", {"gain": 1.0})


def test_worker_commands_are_checked():
    assert commands.decode_command(commands.encode_command(3, "settings", set={"gain": 1})) == {
        "id": 3,
        "cmd": "settings",
        "set": {"gain": 1},
    }
    with pytest.raises(ProtocolError) as unknown:
        commands.decode_command(b'{"id": 1, "cmd": "restart_stream"}')
    assert (
        unknown.value.code == "UNKNOWN_OP" and "known: ['settings', 'trigger_at', 'lockstep']" in unknown.value.message
    )
    for bad in (b"[]", b'{"cmd": "settings"}', b"not json"):
        with pytest.raises(ProtocolError):
            commands.decode_command(bad)
    assert commands.decode_reply(commands.encode_failure(2, "TIMEOUT", "late"))["error"] == "late"
