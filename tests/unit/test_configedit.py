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
    changed = lines.index("gain = 2.5  # set by hand")  # its comment kept
    assert lines[changed + 1 : changed + 4] == [
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


def test_a_changed_line_keeps_its_comment_and_a_whole_number_stays_an_integer(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text('[cameras.left]\nkind = "synthetic"\n  fps = 20   # the grid # of the cell\nnote = "a # b"  # c\n')
    # what the camera answers (floats), and what the user typed (fxis set left fps=25 gain=3)
    save_camera_values(str(path), "left", {"fps": 25.0, "note": "x # y", "gain": 3.0}, given={"fps": 25, "gain": 3})
    assert path.read_text().splitlines() == [
        "[cameras.left]",
        'kind = "synthetic"',
        "  fps = 25   # the grid # of the cell",
        'note = "x # y"  # c',
        "gain = 3",
    ]


def test_a_float_stays_a_float_and_an_integer_in_the_file_stays_one(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text("[cameras.left]\ngain = 1.5\nwidth = 320\nfps = 20\n")
    save_camera_values(str(path), "left", {"gain": 2.0, "width": 322, "fps": 12.5})
    assert path.read_text().splitlines() == ["[cameras.left]", "gain = 2.0", "width = 322", "fps = 12.5"]
    save_camera_values(str(path), "left", {"fps": 10.0})  # the file's 12.5 was a float: as the camera says
    assert "fps = 10.0" in path.read_text()
    assert tomllib.loads(path.read_text())["cameras"]["left"] == {"gain": 2.0, "width": 322, "fps": 10.0}
