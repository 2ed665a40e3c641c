"""A pytest plugin (``-p tests.filetimes`` in pyproject.toml's addopts): the suite's time per
file, printed at its end, so that where the seconds go is seen on every run (issue 37).

Beside each file's seconds, the CPU-seconds its tests and the processes they started and
ended spent (a finished child's CPU is counted when it is reaped): on a 2-core machine the
suite is CPU-bound, so a file's CPU is its real cost to the others.

The seconds are kept in pytest's cache, and the next run starts the longest files first: with a
module's tests on one worker (--dist loadscope), a long file started last would leave the other
workers idle while it finishes."""

import resource
import time
from collections import defaultdict

import pytest

_FILE_SECONDS: dict[str, float] = defaultdict(float)
_FILE_CPU: dict[str, float] = defaultdict(float)
_STARTED: list[float] = []
_CPU_BEFORE: list[float] = []
_CACHE_KEY = "fxis/file_seconds"


def _cpu_s() -> float:
    """This process's CPU and its reaped children's (and theirs), in seconds."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Each phase's report carries the CPU spent since the previous phase ended (in the
    process that ran it: an xdist worker sends it to the controller with the report)."""
    outcome = yield
    now = _cpu_s()
    outcome.get_result().user_properties.append(("cpu_s", now - (_CPU_BEFORE[-1] if _CPU_BEFORE else now)))
    _CPU_BEFORE[:] = [now]


def _file_of(nodeid: str) -> str:
    return nodeid.split("::")[0]


def pytest_sessionstart(session):
    _STARTED.append(time.monotonic())


def pytest_collection_modifyitems(session, config, items):
    """The files that took longest last time first. The sort is stable and a file's tests share
    its key, so each file's tests stay together and in their order (module-scoped services);
    files not timed yet keep their places after them."""
    cache = getattr(config, "cache", None)  # None with -p no:cacheprovider (scripts/test-aarch64.sh)
    seconds = cache.get(_CACHE_KEY, {}) if cache else {}
    if seconds:
        items.sort(key=lambda item: -seconds.get(_file_of(item.nodeid), 0.0))


def pytest_sessionfinish(session):
    """Keeps each file's seconds for the next run's order (on the controller, which saw every
    worker's reports)."""
    cache = getattr(session.config, "cache", None)
    if _FILE_SECONDS and cache and not hasattr(session.config, "workerinput"):
        kept = cache.get(_CACHE_KEY, {})
        kept.update(_FILE_SECONDS)
        cache.set(_CACHE_KEY, kept)


def pytest_runtest_logreport(report):
    """Set-up, call and teardown of every test, summed per file. With xdist this runs on the
    controller with every worker's reports; a file's tests run on one worker (--dist loadscope),
    so its sum is the time it took there."""
    path = _file_of(report.nodeid)
    _FILE_SECONDS[path] += report.duration
    _FILE_CPU[path] += sum(value for key, value in report.user_properties if key == "cpu_s")


def pytest_terminal_summary(terminalreporter):
    if not _FILE_SECONDS or not _STARTED:
        return
    wall = time.monotonic() - _STARTED[0]
    timed = sorted(_FILE_SECONDS.items(), key=lambda item: -item[1])
    shown = [(path, seconds) for path, seconds in timed if seconds >= 1.0]
    cpu = sum(_FILE_CPU.values())
    terminalreporter.section(
        f"time per file: {len(timed)} files, the suite's wall time {wall:.1f} s, {cpu:.0f} CPU-s in all"
    )
    groups: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0])
    for path, seconds in timed:  # per folder of tests (unit, integration, backends, ...)
        group = groups[path.rsplit("/", 1)[0] + "/" if "/" in path else path]  # README.md: a group of its own
        group[0] += seconds
        group[1] += _FILE_CPU[path]
    for folder, (seconds, group_cpu) in sorted(groups.items(), key=lambda item: -item[1][0]):
        terminalreporter.write_line(f"{seconds:8.1f} s {group_cpu:7.1f} CPU-s  {folder} (all of it)")
    for path, seconds in shown:
        terminalreporter.write_line(f"{seconds:8.1f} s {_FILE_CPU[path]:7.1f} CPU-s  {path}")
    if len(shown) < len(timed):
        rest = sum(seconds for _, seconds in timed[len(shown) :])
        rest_cpu = sum(_FILE_CPU[path] for path, _ in timed[len(shown) :])
        terminalreporter.write_line(
            f"{rest:8.1f} s {rest_cpu:7.1f} CPU-s  the other {len(timed) - len(shown)} files, under 1 s each"
        )
