"""bench/network/remote.py's part travel (issue 11): how late t* would be if it were the moment the
request arrived rather than the moment the caller made the call.

A call without ``at`` sends ``t_call``, its moment mapped into the service's clock, and the
service takes t* = t_call; the reply's ``t_request`` is t* in the caller's clock and
``timing["received"]`` the request's arrival (service clock). Per link rate (host A's link
shaped as the size part does), load and encoding, --travel-requests calls ``tuple(wait="none")``
after sleeps U[0, 2 x --travel-sleep-ms]. The call moment is the client's own reading of its
clock as the call begins (its clock is wrapped to record it: our own stamp just before the
call would add whatever a busy machine keeps us waiting in between). Each call gives
  late    arrival - call: what t* would be off by without t_call;
  t_req   t_request - call: 0 when the service used t_call (the mapping's rounding aside);
  true    t* - call on the true clocks (the host's exact offset): the mapping's error too.
Load "busy": another client process on this host pulls raw tuples back to back from the same
service over the same link; a request then travels beside the other's replies and waits for a
service busy sending them: there the difference is large.
Target: every call's |t_req| and |true| within the clock estimate's uncertainty at that call.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import random
import time

from bench.network.size import RATIO_TARGETS
from bench.shared import common
from fxis_shm import Client

RATES = tuple(RATIO_TARGETS)  # the size part's link rates: 1 Gbit and 100 Mbit
LOADS = ("idle", "busy")
PULLER_START_S = 60.0  # the busy client's first tuple must come within this
PULLER_STOP_S = 10.0


def pull_back_to_back(endpoint: str, keys, cams: list[str], timeout: float, stop, pulled, failed) -> None:
    """The busy client (a process of its own): raw tuples, one after the other, until ``stop``."""
    with Client(endpoint, timeout=timeout, keys=keys) as client:
        while not stop.is_set():
            try:
                client.tuple(cams, wait="none")
            except common.REQUEST_ERRORS:
                with failed.get_lock():
                    failed.value += 1
            else:
                with pulled.get_lock():
                    pulled.value += 1


class BusyLink:
    """A second client on this host keeping host A's link full with raw tuples (a context)."""

    def __init__(self, endpoint: str, keys, cams: list[str], timeout: float):
        ctx = multiprocessing.get_context("spawn")  # a fresh process: no ZeroMQ state inherited
        self.stop, self.pulled, self.failed = ctx.Event(), ctx.Value("q", 0), ctx.Value("q", 0)
        self.process = ctx.Process(
            target=pull_back_to_back,
            args=(endpoint, keys, cams, timeout, self.stop, self.pulled, self.failed),
            name="fxis-busy-client",
            daemon=True,
        )
        self.started = self.ended = None
        self.first = 0

    def __enter__(self) -> BusyLink:
        self.process.start()
        deadline = time.monotonic() + PULLER_START_S
        while self.pulled.value == 0:  # busy from its first reply on
            if not self.process.is_alive() or time.monotonic() > deadline:
                self.__exit__()
                raise RuntimeError(f"the busy client got no tuple within {PULLER_START_S:.0f} s")
            common.sleep_ms(20)
        self.started, self.first = time.monotonic(), self.pulled.value
        return self

    def __exit__(self, *exc) -> None:
        self.ended = time.monotonic()
        self.stop.set()
        self.process.join(PULLER_STOP_S)
        if self.process.is_alive():  # stuck in a request: its timeout is longer than our patience
            self.process.terminate()
            self.process.join(PULLER_STOP_S)

    def report(self) -> dict:
        span = (self.ended or time.monotonic()) - (self.started or time.monotonic())
        tuples = self.pulled.value - self.first
        return {"tuples": tuples, "per_s": tuples / span if span > 0 else None, "failed": self.failed.value}


@contextlib.contextmanager
def call_moment(client: Client):
    """The client's clock readings while in the block (a request reads it once, as it begins)."""
    clock, moments = client.clock, []

    def reading() -> int:
        moments.append(clock())
        return moments[-1]

    client.clock = reading
    try:
        yield moments
    finally:
        client.clock = clock


def calls(args, client: Client, cams: list[str], offset_ns: int, rng: random.Random, label: str) -> list[dict]:
    """--travel-requests calls, each after its random sleep: the call moment, the arrival and t*."""
    records = []
    with common.progress(args.travel_requests, f"travel {label}") as bar:
        for i in range(args.travel_requests):
            common.sleep_ms(rng.uniform(0, 2 * args.travel_sleep_ms))
            rec = {"i": i, "error": None}
            try:
                with call_moment(client) as moments:
                    reply = client.tuple(cams, wait="none")
            except common.REQUEST_ERRORS as exc:
                rec["error"] = common.describe_error(exc)
            else:
                called, estimate = moments[0], client.clock_estimate()
                rec.update(
                    late_ms=common.ms(estimate.to_caller(reply.timing["received"]) - called),
                    t_request_us=(reply.t_request - called) / 1e3,
                    true_us=(reply.service_t_request - offset_ns - called) / 1e3,
                    uncertainty_us=estimate.uncertainty_ns / 1e3,
                    rtt_ms=common.ms(client.clock() - called),
                )
            records.append(rec)
            bar.update(1)
    return records


def judged(records: list[dict]) -> dict:
    ok = [r for r in records if r["error"] is None]
    within = [max(abs(r["t_request_us"]), abs(r["true_us"])) <= r["uncertainty_us"] for r in ok]
    return {
        "requests": len(records),
        "failed": len(records) - len(ok),
        "late_ms": common.summary(r["late_ms"] for r in ok),
        "rtt_ms": common.summary(r["rtt_ms"] for r in ok),
        "abs_t_request_us": common.summary(abs(r["t_request_us"]) for r in ok),
        "abs_true_us": common.summary(abs(r["true_us"]) for r in ok),
        "uncertainty_us": common.summary(r["uncertainty_us"] for r in ok),
        "outside_uncertainty": len(within) - sum(within),
        "passed": None if not ok else all(within),
        "records": records,
    }


def travel(args, host, endpoint: str, keys, clients: dict[str, Client], cams: list[str], rng) -> dict:
    """The travel part over host A (``host``, service at ``endpoint``): ``clients`` by encoding."""
    out = {"configs": {}, "busy_client": {}, "targets": []}
    for rate in RATES:
        host.set_rate(rate)
        for load in LOADS:
            busy = BusyLink(endpoint, keys, cams, args.timeout) if load == "busy" else None
            with busy or contextlib.nullcontext():
                for encoding, client in clients.items():
                    label = f"{rate} {load} {encoding}"
                    out["configs"][label] = judged(calls(args, client, cams, host.clock_offset_ns, rng, label))
            if busy:
                out["busy_client"][rate] = busy.report()
    host.set_rate("1gbit")
    for label, r in out["configs"].items():
        out["targets"].append({"config": label, "outside_uncertainty": r["outside_uncertainty"], "passed": r["passed"]})
    print_travel(out, args, cams)
    return out


def print_travel(out: dict, args, cams: list[str]) -> None:
    rows = []
    for label, r in out["configs"].items():
        late, t_req, true, unc = r["late_ms"], r["abs_t_request_us"], r["abs_true_us"], r["uncertainty_us"]
        rows.append(
            [label, late["n"], late["median"], late["p99"], late["max"], t_req["max"], true["p99"], unc["median"]]
        )
    print()
    print(
        common.table(
            ["link load encoding", "n", "late median", "p99", "max", "|t_req| max us", "|true| p99 us", "uncert. us"],
            rows,
            title=f"arrival - call (ms): how late t* would be without t_call; tuples of {' + '.join(cams)} "
            f"wait='none', raw and JPEG q{args.quality}; t_req, true: t* - call (us)",
            digits=3,
        )
    )
    for rate, b in out["busy_client"].items():
        print(f"  [{rate} busy] the other client pulled {common.fmt(b['per_s'])} raw tuples/s (failed {b['failed']})")
    for label, r in out["configs"].items():
        print(
            f"  {common.verdict(r['passed'])} [{label}] t_request = the call moment within the clock "
            f"uncertainty: {r['outside_uncertainty']} of {r['late_ms']['n']} outside; failed {r['failed']}"
        )
