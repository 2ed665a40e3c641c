"""A pytest plugin (``-p tests.filetimes`` in pyproject.toml's addopts): the suite's time per
file, printed at its end, so that where the seconds go is seen on every run (issue 37)."""

import time
from collections import defaultdict

_FILE_SECONDS: dict[str, float] = defaultdict(float)
_STARTED: list[float] = []


def pytest_sessionstart(session):
    _STARTED.append(time.monotonic())


def pytest_runtest_logreport(report):
    """Set-up, call and teardown of every test, summed per file. With xdist this runs on the
    controller with every worker's reports; a file's tests run on one worker (--dist loadscope),
    so its sum is the time it took there."""
    _FILE_SECONDS[report.nodeid.split("::")[0]] += report.duration


def pytest_terminal_summary(terminalreporter):
    if not _FILE_SECONDS or not _STARTED:
        return
    wall = time.monotonic() - _STARTED[0]
    timed = sorted(_FILE_SECONDS.items(), key=lambda item: -item[1])
    shown = [(path, seconds) for path, seconds in timed if seconds >= 1.0]
    terminalreporter.section(f"time per file: {len(timed)} files, the suite's wall time {wall:.1f} s")
    for path, seconds in shown:
        terminalreporter.write_line(f"{seconds:8.1f} s  {path}")
    if len(shown) < len(timed):
        rest = sum(seconds for _, seconds in timed[len(shown) :])
        terminalreporter.write_line(f"{rest:8.1f} s  the other {len(timed) - len(shown)} files, under 1 s each")
