import os

import pytest

from fxis_shm import naming
from fxis_shm.launch import ServiceProcess
from fxis_shm.supervisor import lock_path

SMALL = "width=64,height=48"


def assert_nothing_left(name: str) -> None:
    assert naming.leftovers(name) == [], f"service {name!r} left shared memory behind"
    assert not os.path.exists(lock_path(name)), f"service {name!r} left its lock file"


@pytest.fixture
def start_service(tmp_path):
    """Start real services (``fxis run`` processes); each is stopped and checked for leftovers."""
    started = []

    def start(*args, **kwargs) -> ServiceProcess:
        log = open(tmp_path / f"service{len(started)}.log", "w")
        svc = ServiceProcess(list(args), stderr=log, **kwargs)
        started.append((svc, log))
        return svc.start()

    yield start
    for svc, log in started:
        svc.stop()
        log.close()
        assert_nothing_left(svc.name)


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
