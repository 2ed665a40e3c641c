import os

import pytest

from ..conftest import assert_nothing_left, start_service  # noqa: F401  (shared fixtures)

from fxis_shm.launch import ServiceProcess

SMALL = "width=64,height=48"


@pytest.fixture(scope="module")
def two_cameras():
    """A shared service with two small synthetic cameras at 50 fps, for tests that only read."""
    svc = ServiceProcess(["--camera", f"cam0=synthetic:fps=50,{SMALL}",
                          "--camera", f"cam1=synthetic:fps=50,phase_ms=1,{SMALL}"],
                         stderr=open(os.devnull, "w"))
    svc.start()
    yield svc
    svc.stop()
    assert_nothing_left(svc.name)


def child_pids(svc, role: str) -> list[int]:
    """Pids of the service's children of one role ("camera" or "coordinator")."""
    pids = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as f:
                stat = f.read()
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                cmdline = f.read().split(b"\0")
        except OSError:
            continue
        ppid = int(stat[stat.rfind(b")") + 2 :].split()[1])
        if ppid == svc.proc.pid and f"fxis_shm.workers.{role}".encode() in cmdline:
            pids.append(int(entry))
    return pids
