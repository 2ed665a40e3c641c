"""A pytest plugin (``-p tests.leftovers`` in pyproject.toml's addopts): the run fails if a process
it started is still alive at its end, naming each by command line and parent (issue 42: hook
pools outlived every ``make test``), and ends them.

The suite's processes are this pytest's descendants and every process whose environment carries
this run's mark, ``FXIS_TEST_RUN``, set here before any test starts and inherited by whatever the
tests start: an orphan, reparented to init when its parent died, still carries it. Processes of
other runs, other engineers and the machine carry another mark or none. The pytest that set the
mark checks; with pytest-xdist that is the controller, after its workers ended (they inherited
the mark), so the workers' processes are checked too. A pytest run by a test inherits the mark
and checks nothing."""

import os
import signal
import time

import pytest

from fxis_shm.shm import procstat

RUN_ENV = "FXIS_TEST_RUN"
GRACE_S = 5.0  # processes ending as the run ends (a service stopped by the last teardown) may
_OWNER: list[str] = []  # this run's mark, if this process set it
_SURVIVORS: list[str] = []


def pytest_configure(config):
    """Mark the run (before xdist starts its workers, at session start: they inherit it)."""
    if not os.environ.get(RUN_ENV):
        os.environ[RUN_ENV] = f"{os.getpid()}-{time.time_ns()}"
        _OWNER.append(os.environ[RUN_ENV])


def _marked(pid: int, mark: bytes) -> bool:
    try:
        with open(f"/proc/{pid}/environ", "rb") as f:
            return mark in f.read().split(b"\0")
    except OSError:  # gone, or another user's
        return False


def survivors(mark: str, me: int) -> dict[int, procstat.ProcStat]:
    """The live processes (not zombies) below ``me`` or carrying ``mark``, but ``me``."""
    below, entry = set(procstat.descendants(me)), f"{RUN_ENV}={mark}".encode()
    found = {}
    for name in os.listdir("/proc"):
        if not name.isdigit() or int(name) == me:
            continue
        stat = procstat.read(int(name))
        if stat is not None and stat.running and (stat.pid in below or _marked(stat.pid, entry)):
            if not _ends_with(stat, me):
                found[stat.pid] = stat
    return found


def _ends_with(stat: procstat.ProcStat, me: int) -> bool:
    """Multiprocessing's resource tracker started by this pytest itself (a test used
    multiprocessing in-process): it reads a pipe only this process holds open, so it ends when
    this process does, and cannot end before."""
    return stat.ppid == me and "multiprocessing.resource_tracker" in " ".join(procstat.cmdline(stat.pid))


@pytest.hookimpl(trylast=True)  # after xdist ended its workers
def pytest_sessionfinish(session):
    if not _OWNER:
        return
    deadline = time.monotonic() + GRACE_S
    while (left := survivors(_OWNER[0], os.getpid())) and time.monotonic() < deadline:
        time.sleep(0.1)
    for pid, stat in sorted(left.items()):
        parent = " ".join(procstat.cmdline(stat.ppid))[:100] or "?"
        _SURVIVORS.append(f"pid {pid}: {' '.join(procstat.cmdline(pid)) or stat.name}  (parent {stat.ppid}: {parent})")
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    if left:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter):
    if _SURVIVORS:
        terminalreporter.section("processes the suite started and left running (now killed)", red=True)
        for line in _SURVIVORS:
            terminalreporter.write_line(line)
