"""A pytest plugin for `make mutation` ([tool.mutmut] pytest_add_cli_args): writes which test
killed each mutant to killers.txt in mutmut's working directory (mutants/), one
``MUTANT TEST`` line per failing test, so that scripts/mutation_changed.py can run again
just the mutants a changed test killed. Outside mutmut (no mutant under test) it does nothing."""

from __future__ import annotations

import os


def pytest_runtest_logreport(report) -> None:
    mutant = os.environ.get("MUTANT_UNDER_TEST", "")
    if report.failed and "__mutmut_" in mutant:
        with open("killers.txt", "a") as killers:  # one short append per line: workers do not interleave
            killers.write(f"{mutant} {report.nodeid}\n")
