"""A pytest plugin (``-p tests.rerunlog``, with pytest-rerunfailures' ``--reruns``): every rerun
is written to the file ``--rerun-log`` names, one line each (the test, the phase, the first line
of why it failed), so that `make test` ends by listing them; the whole report (traceback, captured
output) goes to the same path + ``.details``. Only the real-time tier reruns
(tests marked ``realtime``, issue 41): a rerun is the machine's load or a defect, and either is
worth a look."""

from __future__ import annotations


def pytest_addoption(parser):
    parser.addoption("--rerun-log", default=None, help="append a line per rerun test to this file")


class _RerunLog:
    def __init__(self, path: str):
        self.path = path

    def pytest_runtest_logreport(self, report):
        if report.outcome != "rerun":
            return
        crash = getattr(report.longrepr, "reprcrash", None)
        why = crash.message.splitlines()[0] if crash is not None and crash.message else str(report.longrepr)[:200]
        with open(self.path, "a") as log:
            log.write(f"{report.nodeid} ({report.when}): {why}\n")
        with open(self.path + ".details", "a") as details:  # the whole report: a rerun that passed hides it
            details.write(f"==== {report.nodeid} ({report.when})\n{report.longreprtext}\n")
            for name, text in report.sections:
                details.write(f"---- {name}\n{text}\n")


def pytest_configure(config):
    path = config.getoption("--rerun-log")
    if path:
        config.pluginmanager.register(_RerunLog(path), "rerunlog-file")
