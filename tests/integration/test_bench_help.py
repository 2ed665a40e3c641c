"""Every bench answers ``--help`` run from the project root as its README says
(``.venv/bin/python bench/latency/paper.py --help``): its imports, its place in bench/ and its
options parse (issue 37). The benches run at once, a few at a time."""

import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCHES = sorted(str(p.relative_to(ROOT)) for p in ROOT.glob("bench/*/*.py") if "__main__" in p.read_text())

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def answers():
    def run(bench):
        return subprocess.run([sys.executable, bench, "--help"], cwd=ROOT, capture_output=True, text=True, timeout=60)

    with ThreadPoolExecutor(max_workers=4) as pool:
        return dict(zip(BENCHES, pool.map(run, BENCHES)))


def test_the_benches_are_found():
    assert len(BENCHES) >= 18


@pytest.mark.parametrize("bench", BENCHES)
def test_the_bench_answers_help_from_the_project_root(answers, bench):
    done = answers[bench]
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: ") and "--help" in done.stdout
