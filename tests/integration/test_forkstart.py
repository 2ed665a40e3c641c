"""Camera workers and the coordinator start as forks of the supervisor (service/forkstart.py):
children of it, named for their role, holding nothing of it but their readiness pipe, restarted
the same way; FXIS_SPAWN=exec starts them in fresh interpreters as before."""

import os
import signal

import pytest

from fxis_shm.service.servicelock import lock_path
from fxis_shm.shm import procstat

from .conftest import SMALL, child_pids

pytestmark = pytest.mark.integration

CAMERAS = ("--camera", f"a=synthetic:fps=50,{SMALL}", "--camera", f"b=synthetic:fps=50,{SMALL}")


def open_files(pid: int) -> dict[int, str]:
    folder = f"/proc/{pid}/fd"
    return {int(fd): os.readlink(os.path.join(folder, fd)) for fd in os.listdir(folder)}


def test_workers_are_forked_children_of_the_supervisor_named_for_their_role(start_service):
    svc = start_service(*CAMERAS)
    children = svc.children()
    assert set(children) == {"camera:a", "camera:b", "coordinator"}
    names = {key: procstat.read(pid) for key, pid in children.items()}
    assert {key: (stat.name, stat.ppid) for key, stat in names.items()} == {
        "camera:a": ("fxis camera", svc.proc.pid),
        "camera:b": ("fxis camera", svc.proc.pid),
        "coordinator": ("fxis coord", svc.proc.pid),
    }
    with svc.client() as client:
        frames = client.tuple()
    assert set(frames) == {"a", "b"}


def test_a_forked_worker_holds_none_of_the_supervisors_files(start_service):
    svc = start_service(*CAMERAS)
    supervisor = open_files(svc.proc.pid)
    assert lock_path(svc.name) in supervisor.values()  # what the check below looks for is there
    for key, pid in svc.children().items():
        files = open_files(pid)
        assert files[0] == "/dev/null", key  # a worker reads no input
        assert lock_path(svc.name) not in files.values(), f"{key} holds the service's lock"
        inherited = {fd: path for fd, path in files.items() if fd > 2 and supervisor.get(fd) == path}
        assert not inherited, f"{key} kept the supervisor's {inherited}"


def threads_of(pid: int) -> list[str]:
    """The names of a process's threads (/proc/PID/task/*/comm)."""
    tasks = f"/proc/{pid}/task"
    return [open(os.path.join(tasks, tid, "comm")).read().strip() for tid in sorted(os.listdir(tasks))]


def test_the_supervisor_forks_with_no_thread_but_its_main_one(start_service, wait):
    """A fork copies only the forking thread: a lock another thread held stays locked in the child.
    The supervisor has none other (its signals wake its loop through a pipe), at start and at a
    restart's fork alike (issue 42, finding 9)."""
    svc = start_service(*CAMERAS)
    assert len(threads_of(svc.proc.pid)) == 1, threads_of(svc.proc.pid)
    old = svc.children()["camera:a"]
    os.kill(old, signal.SIGKILL)
    wait(lambda: svc.children("running").get("camera:a") not in (None, old), timeout=20, what="camera a forked again")
    assert len(threads_of(svc.proc.pid)) == 1, threads_of(svc.proc.pid)
    assert svc.stop() == 0  # and SIGTERM still stops it, through the wakeup pipe


def test_a_killed_forked_worker_is_forked_again(start_service, wait):
    svc = start_service(*CAMERAS)
    old = svc.children()["camera:a"]
    os.kill(old, signal.SIGKILL)
    wait(lambda: svc.children("running").get("camera:a") not in (None, old), timeout=20, what="camera a restarted")
    new = procstat.read(svc.children()["camera:a"])
    assert (new.name, new.ppid) == ("fxis camera", svc.proc.pid)
    with svc.client() as client:
        assert client.image("a").generation == 2


def test_fxis_spawn_exec_starts_each_worker_in_a_fresh_interpreter(start_service):
    svc = start_service(*CAMERAS, env={**os.environ, "FXIS_SPAWN": "exec"})
    for role in ("camera", "coordinator"):
        for pid in child_pids(svc, role):
            assert f"fxis_shm.workers.{role}" in procstat.cmdline(pid)
    with svc.client() as client:
        assert set(client.tuple()) == {"a", "b"}
