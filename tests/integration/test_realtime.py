"""``fxis run --realtime``: the camera workers' threads and the coordinator's loop really run
SCHED_FIFO at the documented priorities (read back from /proc), hook processes and viewers do
not; where the policy is refused (no CAP_SYS_NICE, RLIMIT_RTPRIO 0) one line says so and the
service runs at normal priority, or ``require`` exits 2 with that line. Needs root, as CI runs:
the refusals are made by dropping CAP_SYS_NICE and lowering RLIMIT_RTPRIO for the service alone."""

import os
import shutil
import subprocess
import sys
from collections import Counter

import pytest

from fxis_shm.service import realtime
from fxis_shm.service.launch import free_tcp_port
from fxis_shm.service.rtpolicy import DEFAULT_PRIORITY
from fxis_shm.shm import procstat

from .conftest import SMALL

# what runs at SCHED_FIFO, read back from /proc: in the real-time tier, alone in a fresh pytest (in the
# parallel pass a camera worker started beside other tests once showed threads at FIFO 99)
pytestmark = [pytest.mark.integration, pytest.mark.realtime]

OTHER = (0, 0)
TIMER, PATH = (1, DEFAULT_PRIORITY), (1, DEFAULT_PRIORITY - 1)  # SCHED_FIFO, priority
TRIGGERED = f"a=synthetic:trigger=software,{SMALL}"
POOLED = f"b=synthetic:fps=20,{SMALL},process=tests.hooks:slow_60ms_pid,process_workers=2"


def without_sys_nice() -> list[str]:
    """A wrapper that runs the service without CAP_SYS_NICE and with RLIMIT_RTPRIO 0."""
    assert os.geteuid() == 0 and shutil.which("setpriv") and shutil.which("prlimit"), (
        "needs root and util-linux's setpriv and prlimit (CI has them)"
    )
    return [
        "prlimit",
        "--rtprio=0:0",
        "setpriv",
        "--inh-caps=-sys_nice",
        "--bounding-set=-sys_nice",
        "--",
    ]


def running(svc, count: int) -> dict[str, int] | None:
    children = svc.children()
    return children if len(children) == count else None


def policies(pid: int) -> Counter:
    return Counter(realtime.threads_of(pid).values())


def test_the_capture_and_request_path_runs_fifo_and_hooks_and_viewers_do_not(start_service, wait):
    svc = start_service("--realtime", "--camera", TRIGGERED, "--camera", POOLED, http=f"127.0.0.1:{free_tcp_port()}")
    children = wait(lambda: running(svc, 4), what="cameras, coordinator, dashboard")
    for camera in ("camera:a", "camera:b"):
        threads = policies(children[camera])
        assert threads[TIMER] == 1, f"{camera}: one trigger timer at {DEFAULT_PRIORITY}: {threads}"
        # the capture loop, the command and trigger listeners, the command socket's I/O thread
        assert threads[PATH] == 4, f"{camera}: {threads}"
        assert set(threads) <= {TIMER, PATH, OTHER}
    coordinator = realtime.threads_of(children["coordinator"])
    assert coordinator[children["coordinator"]] == PATH, "the loop: the coordinator's main thread"
    assert Counter(coordinator.values())[PATH] >= 2, f"and its sockets' I/O thread: {coordinator}"
    hooks = [s.pid for s in procstat.children(children["camera:b"])]
    assert len(hooks) >= 2, "the hook's two processes"
    for pid in [*hooks, children["dashboard"]]:
        assert set(policies(pid)) == {OTHER}, f"{procstat.read(pid)}: {policies(pid)}"
    with svc.client() as client:
        status = client.status()
    processes = status["supervisor"]["processes"]
    assert processes["camera:a"]["sched"]["policy"] == "fifo"
    assert processes["camera:a"]["sched"]["priorities"] == [DEFAULT_PRIORITY, DEFAULT_PRIORITY - 1]
    assert processes["coordinator"]["sched"]["priorities"] == [DEFAULT_PRIORITY - 1]
    assert (processes["dashboard"]["sched"]["policy"], processes["dashboard"]["sched"]["rt_threads"]) == ("other", 0)
    assert status["cameras"]["a"]["sched"] == processes["camera:a"]["sched"]


def test_refused_it_says_so_in_one_line_and_runs_at_normal_priority(start_service, wait, tmp_path):
    svc = start_service("--realtime", "--camera", TRIGGERED, wrapper=without_sys_nice())
    children = wait(lambda: running(svc, 2), what="camera and coordinator")
    for key, pid in children.items():
        assert set(policies(pid)) == {OTHER}, f"{key}: {policies(pid)}"
    said = [line for line in (tmp_path / "service0.log").read_text().splitlines() if "realtime" in line]
    assert said == [
        f"fxis run: --realtime: SCHED_FIFO {DEFAULT_PRIORITY} refused (EPERM: no CAP_SYS_NICE and RLIMIT_RTPRIO 0 "
        f"(below {DEFAULT_PRIORITY})); running at normal priority (docs/deployment.md)"
    ]
    with svc.client() as client:
        assert client.status()["supervisor"]["processes"]["camera:a"]["sched"]["policy"] == "other"


def test_refused_with_require_it_exits_2_with_that_line():
    ports = [str(free_tcp_port()) for _ in range(3)]
    run = subprocess.run(
        [
            *without_sys_nice(),
            sys.executable,
            "-m",
            "fxis_shm.cli",
            "run",
            "--realtime=require",
            "--name",
            f"rt{os.getpid()}",
            "--http",
            "off",
            "--camera",
            TRIGGERED,
            *(f"--{flag}=tcp://127.0.0.1:{port}" for flag, port in zip(("endpoint", "pub", "events"), ports)),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 2, run.stderr
    assert run.stderr.splitlines() == [
        f"fxis run: --realtime=require: SCHED_FIFO {DEFAULT_PRIORITY} refused (EPERM: no CAP_SYS_NICE and "
        f"RLIMIT_RTPRIO 0 (below {DEFAULT_PRIORITY})); not starting (docs/deployment.md says how to grant it)"
    ]


def test_memory_that_cannot_be_locked_safely_is_one_line_and_fifo_goes_on(start_service, wait, tmp_path):
    """Under a finite RLIMIT_MEMLOCK without CAP_IPC_LOCK, mlockall(MCL_FUTURE) would make later
    mappings past the limit fail: memory stays unlocked, and the threads still run FIFO."""
    limit = 64 << 10
    unlockable = [
        "prlimit",
        f"--memlock={limit}:{limit}",
        "setpriv",
        "--inh-caps=-ipc_lock",
        "--bounding-set=-ipc_lock",
    ]
    svc = start_service("--realtime", "--camera", TRIGGERED, wrapper=[*unlockable, "--"])
    children = wait(lambda: running(svc, 2), what="camera and coordinator")
    assert policies(children["camera:a"])[TIMER] == 1
    for pid in children.values():
        with open(f"/proc/{pid}/status") as f:
            assert "VmLck:\t       0 kB" in f.read().splitlines()
    said = [line for line in (tmp_path / "service0.log").read_text().splitlines() if "realtime" in line]
    assert said == [
        f"fxis run: --realtime: SCHED_FIFO {DEFAULT_PRIORITY}, but memory not locked (RLIMIT_MEMLOCK {limit} bytes "
        "and no CAP_IPC_LOCK)"
    ]
