"""The fxis commands against a real service."""

import json
import os
import subprocess

import cv2
import posix_ipc
import pytest

from fxis_shm import read_stamp
from fxis_shm.service.camerakinds import KINDS
from fxis_shm.service.launch import ServiceProcess
from fxis_shm.service.servicelock import lock_path, service_running
from fxis_shm.shm import naming

from .conftest import SMALL, child_pids
from .test_lifecycle import fxis

pytestmark = pytest.mark.integration


def test_status_prints_a_table(two_cameras):
    result = fxis("status", "--endpoint", two_cameras.endpoint)
    assert result.returncode == 0, result.stderr
    clock, header, *rows, scheduling = result.stdout.splitlines()[1:]
    assert clock.startswith("clock CLOCK_MONOTONIC: same clock, offset from this host's CLOCK_MONOTONIC +0.000 ms")
    assert header.split()[:4] == ["camera", "kind", "alive", "shape"]
    assert [r.split()[:4] for r in rows] == [
        ["cam0", "synthetic", "yes", "48x64"],
        ["cam1", "synthetic", "yes", "48x64"],
    ]
    # each process's threads, read from /proc: at normal priority without --realtime
    assert scheduling == "scheduling: camera:cam0 other, camera:cam1 other, coordinator other"


def test_status_json(two_cameras):
    result = fxis("status", "--endpoint", two_cameras.endpoint, "--json")
    status = json.loads(result.stdout)
    assert status["service"] == two_cameras.name and status["clock"] == "CLOCK_MONOTONIC"
    assert status["clock_mapping"] == {
        "method": "same clock",
        "offset_ns": 0,
        "drift_ppm": 0.0,
        "uncertainty_ns": 0,
        "samples": 0,
    }


def test_status_without_a_service_fails_clearly():
    result = fxis("status", "--endpoint", "tcp://127.0.0.1:9", "--timeout", "0.3")
    assert result.returncode == 3 and "no reply" in result.stderr  # a service did not answer (docs/cli.md)


def test_grab_saves_pngs_and_metadata(two_cameras, tmp_path):
    result = fxis("grab", "--endpoint", two_cameras.endpoint, "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    meta = json.loads((tmp_path / "tuple.json").read_text())
    assert set(meta["frames"]) == {"cam0", "cam1"}
    for frame in meta["frames"].values():
        image = cv2.imread(str(tmp_path / frame["file"]), cv2.IMREAD_UNCHANGED)
        assert image.shape == tuple(frame["shape"])
        assert read_stamp(image) == frame["frame_id"]


def test_clean_removes_leftovers():
    name = "cleantest"
    posix_ipc.SharedMemory(f"/fxis.{name}.x.ring", posix_ipc.O_CREX, size=4096).close_fd()
    result = fxis("clean", "--name", name)
    assert result.returncode == 0 and "removed" in result.stdout
    assert naming.leftovers(name) == []
    assert "nothing" in fxis("clean", "--name", name).stdout


def test_clean_removes_every_kind_of_leftover_of_a_killed_service(start_service, wait):
    """kill -9 of the supervisor of a service with a free-running and a software-triggered camera
    leaves its ring segments, their "new frame" and trigger semaphores, the processes' state files
    and a lock file no one holds: `fxis clean` removes them all and the name runs again."""
    first = ServiceProcess(
        ["--camera", f"a=synthetic:{SMALL}", "--camera", f"t=synthetic:trigger=software,{SMALL}"],
        stderr=subprocess.DEVNULL,
    ).start()
    name, children = first.name, child_pids(first, "camera") + child_pids(first, "coordinator")
    first.proc.kill()
    first.proc.wait()
    wait(lambda: not any(os.path.exists(f"/proc/{pid}") for pid in children), what="its children to exit")
    left = set(naming.leftovers(name))
    prefix = os.path.join(naming.SHM_DIR, naming.prefix(name))
    semaphore = os.path.join(naming.SHM_DIR, "sem." + naming.prefix(name))
    kinds = {
        prefix + "a.ring",
        prefix + "t.ring",
        semaphore + "a.new",
        semaphore + "t.new",
        semaphore + "t.trigger",
        naming.supervisor_state_path(name),
    }
    assert kinds <= left, sorted(left)
    assert os.path.exists(lock_path(name))  # the kernel dropped its lock with the process; the file stays
    result = fxis("clean", "--name", name)
    assert result.returncode == 0, result.stderr
    assert {line.removeprefix("removed ") for line in result.stdout.splitlines()} == left
    assert naming.leftovers(name) == []
    assert os.path.exists(lock_path(name)) and not service_running(name)  # the file stays: flock decides
    assert "nothing" in fxis("clean", "--name", name).stdout
    again = start_service("--camera", f"a=synthetic:{SMALL}", name=name)  # stopped and checked by the fixture
    with again.client() as client:
        assert client.image("a").frame_id >= 0


def test_clean_refuses_while_running(two_cameras):
    result = fxis("clean", "--name", two_cameras.name)
    assert result.returncode == 2 and "running" in result.stderr
    assert naming.leftovers(two_cameras.name)


def test_run_help_lists_every_camera_kind_and_its_keys():
    result = fxis("run", "--help")
    for kind in KINDS.values():
        assert f"{kind.name:<10} {kind.description}" in result.stdout
        assert all(key in result.stdout for key in kind.options)


def test_help_lists_commands():
    result = fxis("--help")
    for command in ("run", "status", "grab", "clean"):
        assert command in result.stdout
