"""bench/network/remote.py's verdict pieces (pure): paired differences between configurations, the
rounds a busy machine spoilt, the travel part's check against the clock uncertainty, and the
flattening of targets for --strict."""

import importlib

import pytest


@pytest.fixture(scope="module")
def network():
    return importlib.import_module("bench.network.remote")


@pytest.fixture(scope="module")
def table2():
    return importlib.import_module("bench.network.table2")


@pytest.fixture(scope="module")
def travel():
    return importlib.import_module("bench.network.travel")


def _record(k, eps_ms, tau_ms, miss_ms=0.0, error=None):
    return {
        "k": k,
        "error": error,
        "eps_b_ms": 1.0,
        "eps_ms": {"cam0": eps_ms},
        "tau_w_ms": {"cam0": tau_ms},
        "phase_miss_ms": miss_ms,
    }


class _Exp:
    names = ["cam0"]


def test_configurations_are_compared_round_by_round(table2):
    result = {
        "one host": {"ours": {"records": [_record(0, -10.0, 5.0), _record(1, 20.0, 0.0), _record(2, 3.0, 1.0)]}},
        "remote": {"ours": {"records": [_record(0, -10.2, 5.2), _record(1, 20.2, 0.2), _record(2, 3.2, 1.2)]}},
    }
    diff, se = table2.paired_difference(result, "remote", "ours", "|eps_1|", _Exp)
    assert diff == pytest.approx(0.2) and se == pytest.approx(0.0, abs=1e-9)  # the rounds' spread cancels
    diff, _ = table2.paired_difference(result, "remote", "ours", "tau_w1", _Exp)
    assert diff == pytest.approx(0.2)


def test_a_round_whose_call_missed_its_phase_or_failed_is_left_out(table2):
    result = {
        "one host": {"ours": {"records": [_record(0, 1.0, 0.0), _record(1, 1.0, 0.0), _record(2, 1.0, 0.0)]}},
        "remote": {
            "ours": {
                "records": [
                    _record(0, 1.5, 0.0),
                    _record(1, 30.0, 0.0, miss_ms=17.0),
                    _record(2, 0.0, 0.0, error="RequestTimeout"),
                ]
            }
        },
    }
    diff, se = table2.paired_difference(result, "remote", "ours", "|eps_1|", _Exp)
    assert diff == pytest.approx(0.5) and se is None  # one round left: no spread to tell


def test_every_target_counts_for_strict(network):
    targets = {
        "table2": [{"passed": True}, {"passed": True}],
        "tuples": False,
        "size": [{"passed": True}],
        "clock": {"passed": None},
    }
    assert network.verdicts(targets) == [True, True, False, True, None]


def _call(t_request_us, true_us, uncertainty_us=50.0, error=None):
    return {
        "error": error,
        "late_ms": 3.0,
        "rtt_ms": 5.0,
        "t_request_us": t_request_us,
        "true_us": true_us,
        "uncertainty_us": uncertainty_us,
    }


def test_t_request_must_be_the_call_moment_within_the_uncertainty(travel):
    assert travel.judged([_call(10.0, -40.0), _call(-2.0, 5.0)])["passed"] is True
    late = travel.judged([_call(10.0, 5.0), _call(3000.0, 3000.0)])  # t* = the arrival: t_call ignored
    assert late["passed"] is False and late["outside_uncertainty"] == 1
    mapped_wrong = travel.judged([_call(1.0, 80.0)])  # the mapping off by more than it claims
    assert mapped_wrong["passed"] is False
    assert travel.judged([_call(0, 0, error="RequestTimeout")])["passed"] is None  # nothing measured
