"""Issue 43's small findings, each with its test: the endpoint a config file gave is in the
bag, an MP4 export opens no encoder (no banners) and writes LF lines, ipc:// socket files go
with the service, a reader of stdout that leaves early is no error, grab's tuple.json says how
each frame was captured."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pytest

from fxis_shm.cli import exitcodes
from fxis_shm.service.launch import ServiceProcess

from ..conftest import fxis, wait_until
from .conftest import module_service

pytestmark = pytest.mark.integration

SIZE = "width=128,height=96"


@pytest.fixture(scope="module")
def service():
    yield from module_service(["--camera", f"left=synthetic:fps=30,{SIZE}"])


def test_a_bag_names_the_endpoint_its_config_file_gave(service, tmp_path):
    config = tmp_path / "cell.toml"
    config.write_text(f'endpoint = "{service.endpoint}"\n')
    result = fxis("record", "--config", str(config), "--out", str(tmp_path / "bag"), "--frames", "3")
    assert result.returncode == 0, result.stderr
    metadata = (tmp_path / "bag" / "metadata.yaml").read_text()
    assert service.endpoint in metadata and "None" not in metadata.split("endpoint", 1)[1].splitlines()[0]
    from mcap.reader import make_reader

    with open(tmp_path / "bag" / "bag_0.mcap", "rb") as f:  # the bag's own ``fxis`` record says it too
        records = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    assert records["fxis"]["endpoint"] == records["fxis.begun"]["endpoint"] == service.endpoint


@pytest.mark.parametrize("codec", ["h265", "av1"])
def test_export_opens_no_encoder_and_writes_lf_lines(service, tmp_path, codec):
    bag = tmp_path / "bag"
    recorded = fxis("record", "--endpoint", service.endpoint, "--out", str(bag), "--frames", "10", "--codec", codec)
    assert recorded.returncode == 0, recorded.stderr
    out = tmp_path / "left.mp4"
    result = fxis("export", str(bag), "--camera", "left", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""  # was 21 lines of libx265's or SVT-AV1's banner
    assert len(result.stdout.strip().splitlines()) == 1 and f"({codec})" in result.stdout
    side = (tmp_path / "left.frames.csv").read_bytes()
    assert b"\r" not in side and side.count(b"\n") >= 2


def test_ipc_socket_files_go_with_the_service(tmp_path):
    folder = tmp_path / "ipc"
    folder.mkdir()
    svc = ServiceProcess(
        ["--camera", f"a=synthetic:{SIZE}"],
        endpoint=f"ipc://{folder}/r",
        pub=f"ipc://{folder}/p",
        events=f"ipc://{folder}/e",
        stderr=subprocess.DEVNULL,
    )
    with svc:
        assert sorted(os.listdir(folder)) == ["e", "p", "r"]
        svc.proc.send_signal(signal.SIGINT)  # a clean Ctrl-C
        assert svc.proc.wait(30) == exitcodes.DONE
    assert os.listdir(folder) == []


def test_a_reader_that_leaves_early_is_no_error(service):
    """``fxis get left --json | head -2``: silent, exit 0, as status."""
    for argv in (["get", "left", "--json"], ["status", "--json"]):
        proc = subprocess.Popen(
            [sys.executable, "-m", "fxis_shm.cli", *argv, "--endpoint", service.endpoint],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        proc.stdout.close()  # the reader left before a byte was written
        err = proc.stderr.read().decode()
        assert proc.wait(60) == exitcodes.DONE, err
        assert err == ""


def test_grab_says_how_each_frame_was_captured(service, tmp_path):
    result = fxis("grab", "--endpoint", service.endpoint, "--out", str(tmp_path / "g"))
    assert result.returncode == 0, result.stderr
    frame = json.loads((tmp_path / "g" / "tuple.json").read_text())["frames"]["left"]
    assert frame["capture"] == "free" and frame["t_target"] is None and frame["residual_ns"] is None


def test_grab_of_a_lockstep_camera_gives_its_target_and_residual(start_service, tmp_path):
    svc = start_service("--lockstep", "20", "--camera", f"trig=synthetic:trigger=software,{SIZE}")
    with svc.client() as client:
        wait_until(lambda: client.status()["cameras"]["trig"]["sync"]["lockstep"]["frames"] >= 3, what="grid frames")
    result = fxis("grab", "--endpoint", svc.endpoint, "--out", str(tmp_path / "g"))
    assert result.returncode == 0, result.stderr
    frame = json.loads((tmp_path / "g" / "tuple.json").read_text())["frames"]["trig"]
    assert frame["capture"] == "lockstep" and isinstance(
        frame["t_target"], int
    )  # the grid point, in the service's clock
    assert frame["residual_ns"] == frame["t_capture"] - frame["t_target"]
