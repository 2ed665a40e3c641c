"""``fxis get`` and ``fxis set`` against a running service, and ``--save`` into its config file
(a restarted service starts with the saved values)."""

import json

import pytest

from fxis_shm.cli import exitcodes
from fxis_shm.service.config import tomllib

from ..conftest import fxis

pytestmark = pytest.mark.integration

CONFIG = """# the cell's cameras
[cameras.left]
kind = "synthetic"   # the embedded camera
fps = 50
width = 64
height = 48
gain = 1.0

[cameras.right]
kind = "synthetic"
fps = 50
width = 64
height = 48
"""


def test_get_set_and_save(start_service, tmp_path):
    config = tmp_path / "cell.toml"
    config.write_text(CONFIG)
    svc = start_service("--config", str(config))
    at = ("--endpoint", svc.endpoint)

    shown = fxis("get", "left", *at)
    assert shown.returncode == 0, shown.stderr
    assert "exposure_us" in shown.stdout and "live, 1..1000000 us" in shown.stdout
    assert "width" in shown.stdout and "restart, 16..16384" in shown.stdout
    assert fxis("get", "left", "gain", *at).stdout.strip() == "1.0"

    changed = fxis("set", "left", "exposure_us=4000", "gain=2.5", "--save", "--config", str(config), *at)
    assert changed.returncode == 0, changed.stderr
    assert "exposure_us=4000.0 gain=2.5 (live); saved in" in changed.stdout
    assert fxis("get", "left", "exposure_us", *at).stdout.strip() == "4000.0"
    text = config.read_text()
    assert "# the cell's cameras" in text and 'kind = "synthetic"   # the embedded camera' in text  # kept as it was
    saved = tomllib.loads(text)["cameras"]
    assert saved["left"]["exposure_us"] == 4000.0 and saved["left"]["gain"] == 2.5
    assert "exposure_us" not in saved["right"]

    refused = fxis("set", "left", "exposure_us=0", *at)
    assert refused.returncode == exitcodes.USAGE  # a refused value: change the command (issue 43)
    assert "SETTING_REFUSED: exposure_us=0 is out of range: it allows 1..1000000 us" in refused.stderr
    unknown = fxis("set", "centre", "gain=1", *at)
    assert unknown.returncode == exitcodes.USAGE and "UNKNOWN_CAMERA" in unknown.stderr
    no_file = fxis("set", "left", "gain=1", "--save", *at)
    assert no_file.returncode == exitcodes.USAGE and "give it with --config FILE" in no_file.stderr
    flagged = fxis("set", "left", "gain=1", "--save", "--config", str(tmp_path / "missing.toml"), *at)
    assert flagged.returncode == exitcodes.USAGE and "missing.toml" in flagged.stderr
    no_table = tmp_path / "other.toml"
    no_table.write_text('[cameras.elsewhere]\nkind = "synthetic"\n')
    unsaved = fxis("set", "left", "gain=1", "--save", "--config", str(no_table), *at)
    assert unsaved.returncode == exitcodes.USAGE and "has no [cameras.left] table" in unsaved.stderr
    assert fxis("get", "left", "gain", *at).stdout.strip() == "2.5"  # a change that cannot be saved is not made

    svc.stop()
    again = start_service("--config", str(config))
    restarted = fxis("get", "left", "exposure_us", "gain", "--json", "--endpoint", again.endpoint)
    values = json.loads(restarted.stdout)["values"]
    assert values == {"exposure_us": 4000.0, "gain": 2.5}
