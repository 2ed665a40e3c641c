import os
import subprocess
import sys
import threading
import time
import warnings

import pytest
from hypothesis import settings

from fxis_shm.service.launch import ServiceProcess, draw_from_part
from fxis_shm.service.servicelock import lock_path, service_running
from fxis_shm.shm import naming

# a real ROS 2 node run by its own venv's Python (tests.dds_peer.Peer), not a module to collect
collect_ignore = ["rclpy_peer.py"]

# No time limit per Hypothesis example (its default is 200 ms): on 2 shared cores an example now
# and then waits for a CPU, and a limit on wall-clock time is a performance assert, which lives
# in bench/. The properties and their example counts are unchanged.
settings.register_profile("suite", deadline=None)
settings.load_profile("suite")


PORT_PARTS = 8  # the parallel pass's workers (up to 6), the pure-Python pass, any other run


def port_part() -> int:
    """The part of the port span this pytest process draws from: each worker of the parallel
    pass its own, the pure-Python pass beside them its own, any other run (the real-time tier,
    which runs alone; a run by hand) the last."""
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if worker:
        return int(worker.removeprefix("gw")) % (PORT_PARTS - 2)
    return PORT_PARTS - 2 if os.environ.get("FXIS_PURE_PYTHON") == "1" else PORT_PARTS - 1


draw_from_part(port_part(), PORT_PARTS)


def wait_until(predicate, timeout: float = 10.0, interval: float = 0.02, what: str = "condition"):
    """Poll ``predicate`` until it returns a truthy value; fail after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(interval)


@pytest.fixture
def wait():
    return wait_until


def run_in_threads(target, count: int, timeout: float) -> None:
    """Run ``target`` in ``count`` threads at once; each is joined within ``timeout`` s."""
    threads = [threading.Thread(target=target) for _ in range(count)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout)
    assert not any(t.is_alive() for t in threads), "a thread did not finish in time"


def assert_nothing_left(name: str) -> None:
    assert naming.leftovers(name) == [], f"service {name!r} left shared memory behind"
    assert_unlocked(name)


def assert_unlocked(name: str) -> None:
    """The stopped service ``name`` holds its lock no more. It keeps the lock file (servicelock.py
    says why); a test's name is its own: the file goes, so that runs of the suite pile none up."""
    assert not service_running(name), f"service {name!r} still holds its lock"
    try:
        os.remove(lock_path(name))
    except FileNotFoundError:
        pass


@pytest.fixture
def start_service(tmp_path):
    """Start real services (``fxis run`` processes); each is stopped and checked for leftovers."""
    started = []

    def start(*args, **kwargs) -> ServiceProcess:
        log = open(tmp_path / f"service{len(started)}.log", "w")
        svc = ServiceProcess(list(args), stderr=log, **kwargs)
        started.append((svc, log))
        return svc.start()  # a failed start says what the service wrote to its log

    yield start
    for svc, log in started:
        svc.stop()
        log.close()
        assert_nothing_left(svc.name)


def fxis(*args, timeout: float = 60.0) -> subprocess.CompletedProcess:
    """Run the ``fxis`` command line (as a module, so the venv need not be on PATH)."""
    return subprocess.run(
        [sys.executable, "-m", "fxis_shm.cli", *args], capture_output=True, text=True, timeout=timeout
    )


@pytest.fixture
def emulated_hosts(tmp_path):
    """A ``tests.hosts.Lab``: emulated hosts (namespaces, own clocks, shaped links), all removed
    afterwards, also when the test failed. Fails, saying why, where they cannot be made (not
    root, no time namespaces): these tests need them, and CI runs as root."""
    yield from _lab(tmp_path)


@pytest.fixture(scope="module")
def module_hosts(tmp_path_factory):
    """As ``emulated_hosts``, one Lab for a module's tests that only read from its hosts."""
    yield from _lab(tmp_path_factory.mktemp("hosts"))


def _lab(log_dir):
    from .hosts import HostsUnavailable, Lab

    try:
        lab = Lab(log_dir=str(log_dir))
    except HostsUnavailable as exc:
        pytest.fail(f"emulated hosts unavailable: {exc}", pytrace=False)
    with lab:
        yield lab
    assert lab.leftovers() == [], "emulated hosts left namespaces or links behind"
    for svc in (svc for host in lab.hosts for svc in host.services):
        assert_unlocked(svc.name)


def fxis_run_alone(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    """``fxis run`` expected to stop during start-up: a name and endpoints of its own, so it
    can neither meet a running service nor another test's ports."""
    from fxis_shm.service.launch import free_tcp_port

    endpoints = [f"tcp://127.0.0.1:{free_tcp_port()}" for _ in range(3)]
    name = f"alone{os.getpid()}x{time.monotonic_ns() % 10**6}"
    result = fxis(
        "run",
        "--name",
        name,
        "--endpoint",
        endpoints[0],
        "--pub",
        endpoints[1],
        "--events",
        endpoints[2],
        *args,
        timeout=timeout,
    )
    assert_unlocked(name)  # and its lock file goes
    return result


# A test whose end finds this pytest process's main thread at a real-time policy: something it ran
# left it there without SCHED_RESET_ON_FORK, and every service a later test of the same worker
# started then ran all its threads at SCHED_FIFO 99 (seen twice in full runs, in `fxis status`'s
# scheduling line). The one source found was SVT-AV1's encoder as root (issue 41; kept away by
# fxis_shm/formats/threadsched.py). The process is put back at normal priority and the test named
# in the run's warnings summary, so that another culprit shows.
@pytest.fixture(autouse=True)
def _normal_priority_after_each_test(request):
    yield
    policy = os.sched_getscheduler(0) & ~os.SCHED_RESET_ON_FORK
    if policy != os.SCHED_OTHER:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        warnings.warn(f"{request.node.nodeid} left pytest at scheduling policy {policy}: reset", stacklevel=1)
