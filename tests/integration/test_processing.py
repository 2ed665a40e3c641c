"""Per-camera processing hooks in real camera workers."""

import os

import pytest

from fxis_shm import read_stamp

from ..conftest import fxis_run_alone
from .conftest import SMALL

pytestmark = pytest.mark.integration
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.fixture(autouse=True)
def hooks_importable(monkeypatch):
    """The camera workers import tests.hooks: put the repository on their path."""
    monkeypatch.setenv("PYTHONPATH", REPO + os.pathsep + os.environ.get("PYTHONPATH", ""))


def status_of(svc, camera):
    with svc.client() as client:
        return client.status()["cameras"][camera]


def test_a_hook_that_changes_the_image_fixes_the_layout(start_service):
    svc = start_service("--camera", "a=synthetic:width=128,height=96,process=tests.hooks:half_size")
    assert status_of(svc, "a")["shape"] == [48, 64]
    with svc.client() as client:
        frame = client.image("a")
    assert frame.image.shape == (48, 64) and read_stamp(frame.image) == frame.frame_id


def test_a_hook_can_skip_frames(start_service, wait):
    svc = start_service("--camera", f"a=synthetic:fps=50,{SMALL},process=tests.hooks:even_frames_only")
    wait(lambda: status_of(svc, "a")["frames_stored"] >= 6, what="frames to be stored")
    with svc.client() as client:
        frames = client.sequence("consecutive", camera="a", count=5)
    assert all(f.frame_id % 2 == 0 and read_stamp(f.image) == f.frame_id for f in frames)
    assert [b.frame_id - a.frame_id for a, b in zip(frames, frames[1:])] == [2, 2, 2, 2]


def test_a_hook_that_raises_is_counted_and_the_worker_goes_on(start_service, wait):
    svc = start_service("--camera", f"a=synthetic:fps=50,{SMALL},process=tests.hooks:fail_every_third")
    status = wait(lambda: (s := status_of(svc, "a"))["hook_errors"] >= 3 and s, what="hook errors")
    assert status["alive"] and "every third frame" in status["note"]
    with svc.client() as client:
        frames = client.sequence("consecutive", camera="a", count=4)
    assert all(f.frame_id % 3 != 0 for f in frames)


def test_a_slow_hook_spread_over_processes_keeps_order_and_counts_any_drop(start_service, wait):
    """A 60 ms hook at 20 fps (50 ms apart) over 3 processes: the frames are stored in capture
    order, each after the hook ran on it in one of several processes (not in the worker); a
    frame no process was free for is counted as dropped. How many a loaded machine drops is
    bench/cameras/hook_rate.py's figure."""
    from tests.hooks import pid_of

    svc = start_service("--camera", f"a=synthetic:fps=20,{SMALL},process=tests.hooks:slow_60ms_pid,process_workers=3")
    wait(lambda: status_of(svc, "a")["frames_stored"] >= 25, timeout=20, what="frames through the hook")
    with svc.client() as client:
        frames = client.sequence("consecutive", camera="a", count=15)
    status = status_of(svc, "a")
    ids = [f.frame_id for f in frames]
    assert all(b > a for a, b in zip(ids, ids[1:])), ids  # capture order
    assert all(read_stamp(f.image) == f.frame_id for f in frames)
    assert status["hook_errors"] == 0
    assert ids[-1] - ids[0] + 1 - len(ids) <= status["frames_dropped"]  # a frame not stored is counted
    pids = {pid_of(f.image) for f in frames}
    assert len(pids) >= 2 and status["writer_pid"] not in pids, pids  # spread over processes
    # stored after the hook's 60 ms, counted from the frame's capture
    assert all(f.t_stored - f.t_capture >= 60_000_000 for f in frames)


def test_an_unloadable_hook_stops_start_up_naming_camera_and_key(tmp_path):

    result = fxis_run_alone("--camera", f"a=synthetic:{SMALL},process=no.such:hook")
    assert result.returncode == 2  # a setting to change (docs/cli.md)
    assert "camera 'a'" in result.stderr and "process=no.such:hook" in result.stderr


def test_a_malformed_hook_path_is_a_config_error():
    from .test_lifecycle import fxis

    result = fxis("run", "--camera", "a=synthetic:process=not-a-path")
    assert result.returncode == 2 and "process" in result.stderr
