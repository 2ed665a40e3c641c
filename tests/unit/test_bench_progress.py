"""The benches' progress: a bar on a terminal, two plain lines per stage elsewhere."""

import importlib.util
import pathlib
import sys

BENCH = pathlib.Path(__file__).resolve().parents[2] / "bench"


def _common():
    sys.path.insert(0, str(BENCH))
    try:
        spec = importlib.util.spec_from_file_location("bench_common_under_test", BENCH / "shared" / "common.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module
    finally:
        sys.path.remove(str(BENCH))


def test_off_a_terminal_a_stage_prints_one_line_when_it_starts_and_one_when_it_ends(capsys):
    common = _common()
    with common.progress(3, "latency") as bar:
        for _ in range(3):
            bar.update()
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "latency: 3 steps ..."
    assert err[1].startswith("latency: 3 of 3 done in ")
    assert len(err) == 2 and "\r" not in "".join(err)  # no bar redrawn into the log
