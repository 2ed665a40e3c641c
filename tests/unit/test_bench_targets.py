"""The benches' verdicts: local wake-up times and bench/compare/peers.py's target ratios (pure functions)."""

import pytest

from bench.compare import ours, report, rivals
from bench.latency import wake
from bench.scale import scaling


@pytest.fixture(scope="module")
def bench_modules():
    return {"compare_report": report, "latency_wake": wake, "scaling": scaling}


def test_a_request_waited_only_if_a_frame_it_returns_was_stored_after_it_was_made(bench_modules):
    wake_of = bench_modules["latency_wake"].wake_of
    assert wake_of(1_000, 9_000, [500, 900]) == {"waited": False, "wake_ms": None}
    # the last frame stored after the request (at 6_000 ns) counts: 3_000 ns = 0.003 ms
    assert wake_of(1_000, 9_000, [4_000, 6_000, 800]) == {"waited": True, "wake_ms": 0.003}


def test_wake_targets_judge_median_and_p99_of_copied_and_zero_copy_apart(bench_modules):
    wake = bench_modules["latency_wake"]
    idle = {"copy_ms": {"median": 0.0, "p99": 0.0}, "sleep_late_ms": {"median": 0.0, "p99": 0.0}}
    summary = {
        "all, copied": {"wake_ms": {"median": 0.4, "p99": 2.5}},
        "all, zero-copy": {"wake_ms": {"median": None, "p99": None}},
        "machine": idle,
    }
    verdicts = {t["target"]: (t["passed"], t["ratio"]) for t in wake.targets(summary)}
    assert verdicts["local wake-up median, copied"] == (True, pytest.approx(0.8))
    assert verdicts["local wake-up p99, copied"] == (False, pytest.approx(1.25))
    assert verdicts["local wake-up median, zero-copy"] == (None, None)


def test_wake_limits_add_this_machines_copy_and_scheduler_delay_and_say_so(bench_modules):
    wake = bench_modules["latency_wake"]
    machine = {"copy_ms": {"median": 0.45, "p99": 0.9}, "sleep_late_ms": {"median": 0.1, "p99": 3.0}}
    summary = {
        "all, copied": {"wake_ms": {"median": 0.889, "p99": 2.627}},
        "all, zero-copy": {"wake_ms": {"median": 0.3, "p99": 5.868}},
        "machine": machine,
    }
    got = {t["target"]: t for t in wake.targets(summary)}
    copied_median = got["local wake-up median, copied"]
    assert copied_median["limit_ms"] == pytest.approx(1.05) and copied_median["passed"] is True
    assert copied_median["limit_is"] == "0.5 + scheduler 0.100 + copy 0.450"
    zero_p99 = got["local wake-up p99, zero-copy"]
    assert zero_p99["limit_ms"] == pytest.approx(5.0) and zero_p99["passed"] is False  # 5.868: still too late
    assert zero_p99["limit_is"] == "2 + scheduler p99 3.000"
    assert got["local wake-up p99, copied"]["limit_ms"] == pytest.approx(5.45)  # + the copy's median


def test_the_demo_ends_on_a_verdict_a_newcomer_can_read(bench_modules):
    from bench.latency import paper as latency

    met = [{"target": "x", "passed": True, "value_ms": 0.1, "limit_ms": 0.5}]
    assert latency.verdict_line(met, (1.0, 1.0, 1.0), []).startswith("verdict: all 1 targets met (")
    missed = [*met, {"target": "local wake-up p99, zero-copy", "passed": False, "value_ms": 5.868, "limit_ms": 5.0}]
    line = latency.verdict_line(missed, (4.6, 4.0, 4.0), [])
    assert line.startswith("verdict: 1 of 2 targets missed: local wake-up p99, zero-copy: 5.868 ms > 5.000 ms (")
    assert "load average 4.6 at the start" in line


def result(median_ms):
    return {"summary_ms": {"median": median_ms}}


def test_compare_targets_are_ratios_of_medians_against_their_limits(bench_modules):
    report = bench_modules["compare_report"]
    fx, rv = ours, rivals
    res = {
        fx.LOCAL: result(1.2),
        rv.COPY: result(1.0),
        fx.LOCAL_VIEW: result(0.05),
        fx.TIME: result(0.2),
        fx.TCP: result(3.0),
        rv.IMZ_1: result(1.0),
        rv.IMZ: result(2.0),
    }
    got = {(t["contender"], t["reference"]): t for t in report.targets({report.TARGET_SCENARIO: res})}
    assert got[fx.LOCAL, rv.COPY]["pass"] is True and got[fx.LOCAL, rv.COPY]["ratio"] == pytest.approx(1.2)
    assert got[fx.LOCAL_VIEW, fx.TIME]["pass"] is True  # 0.25 <= 0.3
    assert got[fx.TCP, rv.IMZ_1]["pass"] is False  # 3.0 > 2.0
    assert got[fx.TCP, rv.IMZ]["pass"] is False  # 1.5 > 1.2
    assert got[fx.LATEST, rv.COPY]["pass"] is None  # not measured: no verdict
    assert "n/a" in report.targets_table(list(got.values()))


def test_compare_targets_judge_the_interleaved_medians_and_show_the_hot_loops_beside(bench_modules):
    report, fx = bench_modules["compare_report"], ours
    res = {
        fx.LOCAL_VIEW: {**result(0.05), "hot_ms": {"median": 0.01}},
        fx.LATEST_VIEW: {**result(0.05), "hot_ms": {"median": 0.01}},
        fx.TIME: {**result(0.2), "hot_ms": {"median": 0.1}},
    }
    got = {t["contender"]: t for t in report.targets({report.TARGET_SCENARIO: res})}
    # the same 0.25x: within the zero-copy tuple's 0.3x, not within the zero-copy latest's 0.2x
    assert got[fx.LOCAL_VIEW]["pass"] is True and got[fx.LATEST_VIEW]["pass"] is False
    assert got[fx.LATEST_VIEW]["hot_ratio"] == pytest.approx(0.1) and got[fx.LATEST_VIEW]["hot_pass"] is True
    assert got[fx.TCP]["hot_pass"] is None  # not measured
    assert "hot verdict" in report.targets_table(list(got.values()))


def test_the_scaling_help_describes_every_section_from_its_module(bench_modules):
    scaling = bench_modules["scaling"]
    text = scaling.description()
    for name, module in scaling.SECTIONS.items():
        assert f"  {name:<8} " + module.__doc__.strip().splitlines()[0] in text
