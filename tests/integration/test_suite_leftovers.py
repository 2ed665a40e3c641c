"""The suite's own check (tests/leftovers.py): a pytest run that leaves a process of its own alive,
its child or an orphan, fails naming it by command line and parent, and ends it; a run that
leaves none passes, whatever else the machine runs."""

import os
import subprocess
import sys

import pytest

from fxis_shm.shm import procstat

pytestmark = pytest.mark.integration
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

LEAKY = """
import subprocess, sys

def test_leaves_a_child():
    subprocess.Popen([sys.executable, "-c", "import time; time.sleep(301)"])

def test_leaves_an_orphan():
    subprocess.run(["sh", "-c", "sleep 302 & exit 0"], check=True)
"""

TIDY = """
import subprocess

def test_waits_for_its_child():
    subprocess.run(["sleep", "0.1"], check=True)
"""


def run_pytest(tmp_path, source: str) -> subprocess.CompletedProcess:
    """A pytest of its own over ``source``, with the plugin (its mark not inherited from this run)."""
    (tmp_path / "test_it.py").write_text(source)
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    env = {k: v for k, v in os.environ.items() if k != "FXIS_TEST_RUN"}
    env["PYTHONPATH"] = REPO + os.pathsep + env.get("PYTHONPATH", "")
    plugins = ["-p", "no:xdist", "-p", "no:cacheprovider", "-p", "tests.leftovers"]
    command = [sys.executable, "-m", "pytest", "-q", *plugins]
    return subprocess.run(
        [*command, str(tmp_path / "test_it.py")], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120
    )


def test_a_run_that_leaves_processes_fails_naming_them_and_ends_them(tmp_path):
    result = run_pytest(tmp_path, LEAKY)
    assert result.returncode == 1, result.stdout
    assert "2 passed" in result.stdout  # the tests themselves passed: the check failed the run
    lines = [line for line in result.stdout.splitlines() if line.startswith("pid ")]
    assert len(lines) == 2, result.stdout
    child, orphan = sorted(lines, key=lambda line: "sleep 302" in line)
    assert "import time; time.sleep(301)" in child and "(parent " in child
    assert "sleep 302" in orphan
    for line in lines:
        pid = int(line.split()[1].rstrip(":"))
        stat = procstat.read(pid)
        assert stat is None or not stat.running, f"{line}: still alive"


def test_a_run_that_leaves_none_passes_beside_other_processes(tmp_path):
    other = subprocess.Popen(["sleep", "60"])  # this run's, not the inner run's: not its business
    try:
        result = run_pytest(tmp_path, TIDY)
    finally:
        other.kill()
        other.wait()
    assert result.returncode == 0, result.stdout
    assert "left running" not in result.stdout
