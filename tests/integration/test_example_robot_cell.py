"""examples/robot_cell runs end to end: service, vision node and robot (the paper's Fig. 1)."""

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import assert_nothing_left

pytestmark = pytest.mark.integration

RUN = Path(__file__).resolve().parents[2] / "examples" / "robot_cell" / "run.py"
SHIFT = 24


def run_example(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    proc = subprocess.Popen(
        [sys.executable, str(RUN), *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGTERM)  # run.py stops the service and the vision node on SIGTERM
        try:
            out, err = proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
        pytest.fail(f"run.py did not finish within {timeout} s\nstdout:\n{out}\nstderr:\n{err}")
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def test_every_request_gets_a_result_with_the_disparity_of_the_pair():
    name = f"robotcelltest{os.getpid()}"
    done = run_example(
        "--width", "640", "--height", "480", "-n", "5", "--shift", str(SHIFT), "--timeout", "10", "--name", name
    )
    report = f"stdout:\n{done.stdout}\nstderr:\n{done.stderr}"
    assert done.returncode == 0, report
    results = [line for line in done.stdout.splitlines() if line.startswith("result ")]
    assert len(results) == 5, report
    for line in results:
        assert abs(float(re.search(r"disparity\s+(-?[\d.]+) px", line)[1]) - SHIFT) <= 1, line
    mean = re.search(r"^disparity: mean (-?[\d.]+) px", done.stdout, re.MULTILINE)
    assert mean and abs(float(mean[1]) - SHIFT) <= 1, report
    assert re.search(r"^latency: n 5, median [\d.]+ ms, p90 [\d.]+ ms, max [\d.]+ ms$", done.stdout, re.MULTILINE), (
        report
    )
    assert "vision: stopped by SIGTERM" in done.stderr, report
    assert_nothing_left(name)
