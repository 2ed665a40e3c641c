"""The networked case (issue 11): a client on another host, with a clock of its own, over a
rate-limited link; a tuple of cameras on two hosts; raw against JPEG frames.

The other hosts are emulated (tests/hosts.py): network namespaces on veth links shaped with
tc's token bucket (no added delay: this kernel has no netem), each with its own
CLOCK_MONOTONIC (a time namespace, ahead of ours by --offset-s, so the true offset is known
exactly) and /dev/shm, addresses of TEST-NET-2, services with CurveZMQ keys. Needs root.

Host A (clock +offset) runs cam0 and cam1, as bench/latency.py's service (20 fps, 1360x1024
mono8, phases 0 and 1 ms, jitter +/-0.3 ms, 20 slots); host B (clock +2*offset) runs cam2.
This process is the client, on the root namespace's clock. Parts (--parts):

  table2  the paper's Table II (bench/latency_paper.py's request and metrics, its sleeps and
          spike rule), policy "ours" unless --policies says otherwise, for three configurations:
          one host (the same cameras served on this host; the client reads locally), remote raw
          and remote JPEG (host A over 1 Gbit). --requests rounds; in each round every
          configuration, after its own random sleep, calls at the same phase of its cameras'
          frame period (drawn per round), so the configurations are compared request by request
          (paired) rather than by means that wander over a frame period. Target: the remote
          means of eps_b, |eps_j| and tau_w within 0.5 ms of the one host's (paired mean
          difference, printed with its standard error); 0 spikes.
  tuples  --tuple-requests tuples of cam0 (host A) and cam2 (host B) through one client over
          both services, each after a sleep U[0, 2 x --tuple-sleep-ms]. The true skew comes
          from the services' own stamps and the exact offsets; the least the cameras allow is
          the shortest arc of the frame period covering their phases as observed in true time
          (bench/latency.py's definition; the two services start at different moments, so
          their relative phase is whatever it is). Target: 0 spikes (true skew > least + 2 ms).
  size    round trip and bytes per tuple of cam0+cam1 (wait="none") raw and JPEG (--quality)
          over 1 Gbit and 100 Mbit, --size-requests each. Bytes: what the link carried from
          host A (the shaper's counter: TCP, CurveZMQ and headers included) per request.
          Targets: JPEG/raw mean round trip <= 0.6x on 1 Gbit, <= 0.25x on 100 Mbit.
  clock   (always) every client's clock estimate against the true offset, sampled every
          --clock-every s from the first remote client on, while the other parts run; after
          them the client keeps asking host A for tuples at the paper's pace until --minutes
          have passed. Error = the estimate's mapping of "now" minus the true one.
          Target: p99 |error| <= 0.1 ms.

Prints a table per part with PASS/FAIL per target; writes network.json to --out, and the
services' logs to network-logs/ and network.local.log there.
Exit status: 0 when the run completed; 1 if a request failed (or, with --strict, a target
failed; or emulated hosts cannot be made here); 2 on bad flags.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import random
import shutil
import statistics
import sys
import threading
import time

if __package__:
    from . import _common as common, latency_paper as paper
else:  # run as a script, or loaded from its path
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import _common as common
    import latency_paper as paper
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # for tests.hosts
from fxis_shm import Client  # noqa: E402
from tests.hosts import HostsUnavailable, Lab  # noqa: E402

PARTS = ("table2", "tuples", "size")
TABLE_II_TOLERANCE_MS = 0.5
CLOCK_TARGET_MS = 0.1
TUPLE_TARGET_REQUESTS = 1000
RATIO_TARGETS = {"1gbit": 0.6, "100mbit": 0.25}


def parse_parts(text: str) -> list[str]:
    names = [x.strip() for x in text.split(",") if x.strip()]
    unknown = [x for x in names if x not in PARTS]
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown part(s) {', '.join(unknown)}: use {', '.join(PARTS)}")
    return names


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="network.py", description=__doc__, formatter_class=common.HelpFormatter)
    p.add_argument("--parts", type=parse_parts, default=",".join(PARTS), help="comma list of " + ", ".join(PARTS))
    p.add_argument(
        "--minutes",
        type=common.positive_float,
        default=5.0,
        help="the clock estimate is watched for at least this long (the target: 5)",
    )
    p.add_argument("--clock-every", type=common.positive_float, default=0.5, help="clock samples every S s")
    p.add_argument(
        "--offset-s",
        type=common.positive_int,
        default=1000,
        help="host A's clock is this many seconds ahead of ours, host B's twice as many",
    )
    p.add_argument("--quality", type=int, default=90, help="JPEG quality")
    t2 = p.add_argument_group("table2 (as bench/latency.py)")
    t2.add_argument(
        "-n",
        "--requests",
        type=common.positive_int,
        default=300,
        help="rounds, each one request per configuration (the paper: 100 requests; tau_w "
        "spreads over a frame period, so telling 0.5 ms apart takes a few hundred)",
    )
    t2.add_argument("--sleep-ms", type=common.nonnegative_float, default=180.0, help="tau_sleep, ms")
    t2.add_argument("--fluct-ms", type=common.nonnegative_float, default=50.0, help="tau_mf, ms")
    t2.add_argument(
        "--policies", type=paper.parse_policies, default="ours", help="comma list of paper, ours (or 'both')"
    )
    tu = p.add_argument_group("tuples")
    tu.add_argument("--tuple-requests", type=common.positive_int, default=1000)
    tu.add_argument(
        "--tuple-sleep-ms",
        type=common.nonnegative_float,
        default=40.0,
        help="mean sleep before each two-host tuple, ms",
    )
    p.add_argument("--size-requests", type=common.positive_int, default=20, help="requests per size configuration")
    cams = p.add_argument_group("cameras")
    cams.add_argument("--fps", type=common.positive_float, default=20.0)
    cams.add_argument("--jitter-ms", type=common.nonnegative_float, default=0.3)
    cams.add_argument("--width", type=common.positive_int, default=1360)
    cams.add_argument("--height", type=common.positive_int, default=1024)
    cams.add_argument("--slots", type=common.positive_int, default=20)
    p.add_argument("--strict", action="store_true", help="exit 1 if a target fails")
    common.add_output_args(p)
    return p


# ---- the clock estimates, watched in the background ---------------------------------------


class ClockWatch:
    """Samples every watched client's estimate for an endpoint against the true offset."""

    def __init__(self, every_s: float):
        self.every_s, self.samples, self.started = every_s, [], None
        self._watched: list[tuple[str, Client, str, int]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="clock-watch", daemon=True)

    def watch(self, label: str, client: Client, endpoint: str, true_offset_ns: int) -> None:
        client.clock_estimate()  # the first estimate here: later reads in the thread only read it
        self._watched.append((label, client, endpoint, true_offset_ns))
        if self.started is None:
            self.started = time.monotonic()
            self._thread.start()

    def unwatch(self, client: Client) -> None:
        self._watched = [w for w in self._watched if w[1] is not client]

    def _loop(self) -> None:
        while not self._stop.wait(self.every_s):
            for label, client, endpoint, true in list(self._watched):
                estimate = client.clocks.get(endpoint)
                if estimate is None or estimate.method != "estimated":
                    continue
                now = time.monotonic_ns()
                error = estimate.to_service(now) - now - true
                self.samples.append(
                    {
                        "t": now,
                        "client": label,
                        "endpoint": endpoint,
                        "error_ns": error,
                        "uncertainty_ns": estimate.uncertainty_ns,
                        "drift_ppm": estimate.drift_ppm,
                    }
                )

    def elapsed_s(self) -> float:
        return 0.0 if self.started is None else time.monotonic() - self.started

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(5)

    def report(self) -> dict:
        keys = sorted({(s["client"], s["endpoint"]) for s in self.samples})
        rows = {f"{c} {e}": [s for s in self.samples if (s["client"], s["endpoint"]) == (c, e)] for c, e in keys}
        rows["all"] = self.samples
        out = {}
        for name, samples in rows.items():
            out[name] = {
                "abs_error_ms": common.summary(abs(common.ms(s["error_ns"])) for s in samples),
                "uncertainty_ms": common.summary(common.ms(s["uncertainty_ns"]) for s in samples),
            }
        p99 = out["all"]["abs_error_ms"]["p99"]
        out["target"] = {
            "p99_abs_error_ms": p99,
            "limit_ms": CLOCK_TARGET_MS,
            "watched_s": self.elapsed_s(),
            "passed": None if p99 is None else p99 <= CLOCK_TARGET_MS,
        }
        return out


def print_clock(report: dict, minutes: float) -> None:
    rows = [
        [
            name,
            r["abs_error_ms"]["n"],
            r["abs_error_ms"]["median"],
            r["abs_error_ms"]["p99"],
            r["abs_error_ms"]["max"],
            r["uncertainty_ms"]["median"],
        ]
        for name, r in report.items()
        if name != "target"
    ]
    print(
        common.table(
            ["client endpoint", "samples", "|err| median", "p99", "max", "uncert. median"],
            rows,
            title="clock estimate error against the true offset, ms",
            digits=4,
        )
    )
    t = report["target"]
    watched = t["watched_s"] / 60
    print(
        f"  {common.verdict(t['passed'])} clock: p99 |error| {common.fmt(t['p99_abs_error_ms'], 4)} <= "
        f"{CLOCK_TARGET_MS} ms over {watched:.1f} min"
        + ("" if watched >= minutes - 1e-9 else f" (short of --minutes {minutes:g})")
    )


# ---- table2 ---------------------------------------------------------------------------------

ANCHOR_FRAMES = 10  # consecutive frames that fix a camera's phase (jitter averages out)
SPIN_MS = 2.0  # the end of each sleep is spent awake, so that calls come at their phase
PHASE_TOLERANCE_MS = 1.0  # a round counts in the comparison if every call came this close to it


def camera_anchor(client: Client, exp) -> int:
    """The phase of the first camera's frame times in the caller's clock, ns mod the period:
    the mean of (t_capture - frames since the first x period) over consecutive frames."""
    frames = client.sequence("consecutive", camera=exp.names[0], count=ANCHOR_FRAMES)
    first = frames[0].frame_id
    return round(statistics.mean(f.t_capture - (f.frame_id - first) * exp.period_ns for f in frames)) % exp.period_ns


def paired_run(args, configs: dict[str, Client], exp, kinds_of: dict, rng: random.Random) -> list[dict]:
    """The paper's requests (bench/latency_paper.py's measure) in rounds: a round draws one
    phase of the frame period, and every configuration, after its own sleep of the paper's
    law, calls at the next moment of that phase against its own cameras. The configurations
    then differ by their path, not by when they happened to ask (|eps_j| and tau_w spread over
    a whole frame period: unpaired, telling 0.5 ms apart takes thousands of requests)."""
    anchors = {label: camera_anchor(client, exp) for label, client in configs.items()}
    records = []
    with common.progress(args.requests * len(args.policies) * len(configs), "Table II, paired") as bar:
        for k in range(args.requests):
            phase = rng.randrange(exp.period_ns)
            for pol in args.policies:
                for label, client in configs.items():
                    start = time.monotonic_ns()
                    due = start + round((args.sleep_ms + rng.uniform(-args.fluct_ms, args.fluct_ms)) * 1e6)
                    due += (anchors[label] + phase - due) % exp.period_ns
                    common.sleep_ms(common.ms(due - time.monotonic_ns()) - SPIN_MS)
                    while time.monotonic_ns() < due:  # the last stretch awake: a sleep may overshoot
                        pass
                    rec = paper.measure(client, exp, pol, kinds_of)
                    rec.update(
                        i=len(records),
                        k=k,
                        path=label,
                        phase_ms=common.ms(phase),
                        sleep_ms=common.ms(rec["t_send"] - start),
                    )
                    if rec["error"] is None:  # how far from the round's phase the call came (a loaded machine)
                        miss = (rec["t_star"] - anchors[label] - phase) % exp.period_ns
                        rec["phase_miss_ms"] = common.ms(miss - exp.period_ns if miss > exp.period_ns // 2 else miss)
                    records.append(rec)
                    bar.update(1)
    return records


def table_ii(args, configs: dict[str, Client], exp, kinds_of: dict, rng: random.Random) -> dict:
    """Table II per configuration (label -> client), from paired rounds."""
    records = paired_run(args, configs, exp, kinds_of, rng)
    out = {}
    for label in configs:
        out[label] = {}
        for pol in args.policies:
            mine = [r for r in records if (r["policy"], r["path"]) == (pol, label)]
            recs = [r for r in mine if r["error"] is None]
            rows = paper.policy_rows(recs, exp)
            out[label][pol] = {
                "rows": rows,
                "spikes": sum(r["spike"] for r in recs),
                "failed": len(mine) - len(recs),
                "rtt_ms": common.summary(r["rtt_ms"] for r in recs),
                "paths": sorted({r["came_by"] for r in recs}),
                "records": mine,
            }
            print()
            print(paper.format_table_ii((pol, label), rows, exp, len(recs)))
    return out


def metric_values(rec: dict, exp) -> dict:
    """One request's Table II metrics, named as paper.policy_rows names them."""
    values = {"eps_b": rec["eps_b_ms"]}
    for j, cam in enumerate(exp.names, 1):
        values[f"|eps_{j}|"] = abs(rec["eps_ms"][cam])
    for j, cam in enumerate(exp.names, 1):
        values[f"tau_w{j}"] = rec["tau_w_ms"][cam]
    return values


def paired_difference(result: dict, label: str, pol: str, metric: str, exp) -> tuple[float | None, float | None]:
    """Mean over rounds of (``label``'s value - the one host's) and its standard error."""

    def by_round(config):
        return {
            r["k"]: metric_values(r, exp)[metric]
            for r in result[config][pol]["records"]
            if r["error"] is None and abs(r["phase_miss_ms"]) <= PHASE_TOLERANCE_MS
        }

    ours, base = by_round(label), by_round("one host")
    diffs = [ours[k] - base[k] for k in ours.keys() & base.keys()]
    if not diffs:
        return None, None
    se = statistics.stdev(diffs) / math.sqrt(len(diffs)) if len(diffs) > 1 else None
    return statistics.mean(diffs), se


def compare_table_ii(result: dict, policies: list[str], exp) -> list[dict]:
    """Remote means against the one host's, and the spikes of every configuration."""
    targets = []
    for pol in policies:
        base = result["one host"][pol]["rows"]
        remote = [label for label in result if label != "one host"]
        rows = []
        for metric in base:
            if metric == "eps'_b":
                continue
            row = [metric, base[metric]["mean"]]
            for label in remote:
                other = result[label][pol]["rows"][metric]
                diff, se = paired_difference(result, label, pol, metric, exp)
                passed = None if diff is None else abs(diff) <= TABLE_II_TOLERANCE_MS
                targets.append(
                    {
                        "policy": pol,
                        "config": label,
                        "metric": metric,
                        "diff_ms": diff,
                        "standard_error_ms": se,
                        "passed": passed,
                    }
                )
                row += [other["mean"], diff, se, common.verdict(passed)]
            rows.append(row)
        header = ["metric", "one host"] + [h for label in remote for h in (label, "diff", "+/- SE", "")]
        print()
        print(
            common.table(
                header,
                rows,
                title=f"Table II means, policy {pol!r}, ms: remote against one host "
                f"(target |diff| <= {TABLE_II_TOLERANCE_MS} ms; diff: mean over "
                f"paired rounds, SE its standard error)",
            )
        )
        for label, r in result.items():
            late = sum(abs(x.get("phase_miss_ms", 0)) > PHASE_TOLERANCE_MS for x in r[pol]["records"])
            if late:
                print(
                    f"  [{label}] {late} call(s) more than {PHASE_TOLERANCE_MS} ms off their round's phase "
                    f"(the machine was busy): those rounds are left out of the differences"
                )
        worst_se = max((t["standard_error_ms"] or 0) for t in targets if "standard_error_ms" in t)
        if 2 * worst_se > TABLE_II_TOLERANCE_MS:
            print(
                f"  note: a standard error of up to {worst_se:.2f} ms: too few requests to tell a "
                f"{TABLE_II_TOLERANCE_MS} ms difference from chance; raise -n"
            )
        for label, r in result.items():
            spikes = r[pol]["spikes"]
            targets.append({"policy": pol, "config": label, "metric": "spikes", "value": spikes, "passed": spikes == 0})
            print(
                f"  {common.verdict(spikes == 0)} [{label}] {pol}: {spikes} spike(s); round trip mean "
                f"{common.fmt(r[pol]['rtt_ms']['mean'])} ms; came by {'/'.join(r[pol]['paths'])}; "
                f"failed {r[pol]['failed']}"
            )
    return targets


# ---- tuples across two hosts ----------------------------------------------------------------


def two_host_tuples(args, client: Client, offsets: dict[str, int], rng: random.Random) -> dict:
    cams = list(offsets)
    records = []
    with common.progress(args.tuple_requests, "two-host tuples") as bar:
        for i in range(args.tuple_requests):
            common.sleep_ms(rng.uniform(0, 2 * args.tuple_sleep_ms))
            rec = {"i": i, "error": None}
            try:
                pair = client.tuple(cams)
            except common.REQUEST_ERRORS as exc:
                rec["error"] = common.describe_error(exc)
            else:
                true = {c: pair[c].service_t_capture - offsets[c] for c in cams}
                rec.update(
                    frames={c: {"t_capture": true[c], "frame_id": pair[c].frame_id} for c in cams},
                    true_skew_ms=common.ms(max(true.values()) - min(true.values())),
                    mapped_skew_ms=common.ms(pair.skew_ns),
                )
            records.append(rec)
            bar.update(1)
    ok = [r for r in records if r["error"] is None]
    exp = paper.Experiment(cams, args.fps, [0.0] * len(cams), args.jitter_ms)
    phases = paper.observed_phases(ok, exp)
    least = phases["min_covering_arc_ms"] if phases else None
    limit = None if least is None else least + paper.SPIKE_MARGIN_MS
    spikes = sum(r["true_skew_ms"] > limit for r in ok) if ok else None
    out = {
        "cameras": cams,
        "requests": len(records),
        "failed": len(records) - len(ok),
        "least_allowed_skew_ms": least,
        "spike_limit_ms": limit,
        "spikes": spikes,
        "observed_phases": phases,
        "true_skew_ms": common.summary(r["true_skew_ms"] for r in ok),
        "mapped_minus_true_skew_ms": common.summary(r["mapped_skew_ms"] - r["true_skew_ms"] for r in ok),
        "passed": None if spikes is None or len(records) < TUPLE_TARGET_REQUESTS else spikes == 0,
        "records": records,
    }
    s = out["true_skew_ms"]
    print()
    print(
        common.table(
            ["", "n", "min", "median", "p99", "max"],
            [
                ["true skew", s["n"], s["min"], s["median"], s["p99"], s["max"]],
                ["mapped - true", *(out["mapped_minus_true_skew_ms"][k] for k in ("n", "min", "median", "p99", "max"))],
            ],
            title=f"two-host tuples {' + '.join(cams)}, ms; least the cameras allow {common.fmt(least)} ms",
            digits=3,
        )
    )
    print(
        f"  {common.verdict(out['passed'])} two hosts: {spikes} spike(s) (true skew > {common.fmt(limit)} ms) in "
        f"{len(ok)} requests (target: 0 in >= {TUPLE_TARGET_REQUESTS}; fewer: not judged); failed {out['failed']}"
    )
    return out


# ---- size: raw against JPEG -----------------------------------------------------------------


def sizes(args, host, clients: dict[str, Client], cams: list[str]) -> dict:
    out = {"configs": {}, "targets": []}
    rows = []
    for rate in RATIO_TARGETS:
        host.set_rate(rate)
        for encoding, client in clients.items():
            client.tuple(cams, wait="none")  # warm up: the link's queue and the encoder's
            rtts, before = [], host.link_bytes()["from_host"]
            for _ in range(args.size_requests):
                sent = time.monotonic_ns()
                client.tuple(cams, wait="none")
                rtts.append(common.ms(time.monotonic_ns() - sent))
            per_request = (host.link_bytes()["from_host"] - before) / args.size_requests
            out["configs"][f"{rate} {encoding}"] = {"rtt_ms": common.summary(rtts), "link_bytes": per_request}
            rows.append(
                [
                    f"{rate} {encoding}",
                    args.size_requests,
                    common.summary(rtts)["mean"],
                    common.summary(rtts)["p99"],
                    per_request / 1e6,
                ]
            )
    host.set_rate("1gbit")
    print()
    print(
        common.table(
            ["link encoding", "n", "rtt mean", "p99", "MB/tuple"],
            rows,
            title=f"round trip (ms) and link bytes per tuple of {' + '.join(cams)} "
            f"({args.width}x{args.height} mono8), raw and JPEG q{args.quality}",
            digits=3,
        )
    )
    for rate, limit in RATIO_TARGETS.items():
        raw, jpeg = (out["configs"][f"{rate} {e}"] for e in clients)
        ratio = jpeg["rtt_ms"]["mean"] / raw["rtt_ms"]["mean"]
        bytes_ratio = jpeg["link_bytes"] / raw["link_bytes"] if raw["link_bytes"] else None
        passed = ratio <= limit
        out["targets"].append(
            {"rate": rate, "rtt_ratio": ratio, "bytes_ratio": bytes_ratio, "limit": limit, "passed": passed}
        )
        print(
            f"  {common.verdict(passed)} {rate}: JPEG/raw round trip {ratio:.3f}x <= {limit}x "
            f"(bytes {common.fmt(bytes_ratio, 3)}x)"
        )
    return out


# ---- main -----------------------------------------------------------------------------------


def keep_asking(args, client: Client, cams: list[str], watch: ClockWatch, rng: random.Random) -> int:
    """Tuples at the paper's pace until the clock has been watched for --minutes; returns failures."""
    failed = 0
    while watch.elapsed_s() < args.minutes * 60:
        common.sleep_ms(args.sleep_ms + rng.uniform(-args.fluct_ms, args.fluct_ms))
        try:
            client.tuple(cams)
        except common.REQUEST_ERRORS:
            failed += 1
    return failed


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = common.parse_args(p, argv)
    if isinstance(args, int):
        return args
    if not 1 <= args.quality <= 100:
        return common.usage_error(p, f"--quality must be 1..100, got {args.quality}")
    out = common.ensure_dir(args.out)
    rng = random.Random(args.seed)
    names = ["cam0", "cam1"]
    exp = paper.Experiment(names, args.fps, [0.0, 1.0], args.jitter_ms)
    cam_flags = common.synthetic_camera_flags(names, args.fps, args.width, args.height, [0.0, 1.0], args.jitter_ms) + [
        "--slots",
        str(args.slots),
    ]
    host_info, started = common.host_info(), time.time()
    result = {
        "benchmark": "network",
        "started_unix": started,
        "settings": vars(args),
        "host": host_info,
        "experiment": exp.as_dict(),
        "targets": {},
    }
    watch = ClockWatch(args.clock_every)
    failed = 0
    print(
        f"network: client on this host; host A clock +{args.offset_s} s (cam0, cam1), host B clock "
        f"+{2 * args.offset_s} s (cam2); links 1 Gbit unless said; seed {args.seed}"
    )
    print(common.code_line(host_info["code"]))
    try:
        with contextlib.ExitStack() as stack:
            logs = os.path.join(out, "network-logs")  # the emulated hosts' service logs, of this run only
            shutil.rmtree(logs, ignore_errors=True)
            lab = stack.enter_context(Lab(log_dir=common.ensure_dir(logs)))
            stack.callback(watch.stop)
            a = lab.host(clock_offset_s=args.offset_s, rate="1gbit")
            svc_a = a.service(*cam_flags)
            remote = {
                enc: stack.enter_context(
                    Client(
                        svc_a.endpoint, timeout=args.timeout, keys=lab.client_keys, encoding=enc, quality=args.quality
                    )
                )
                for enc in ("raw", "jpeg")
            }
            for enc, client in remote.items():
                watch.watch(f"A {enc}", client, svc_a.endpoint, a.clock_offset_ns)
            status = common.wait_until_streaming(remote["raw"])
            kinds_of = {cam: c["kind"] for cam, c in status["cameras"].items()}
            if "table2" in args.parts:
                with common.service(None, cam_flags, os.path.join(out, "network.local.log"), args.timeout) as (
                    local,
                    _,
                ):
                    common.wait_until_streaming(local)
                    t2 = table_ii(
                        args,
                        {"one host": local, "remote raw": remote["raw"], "remote jpeg": remote["jpeg"]},
                        exp,
                        kinds_of,
                        rng,
                    )
                result["table2"] = t2
                result["targets"]["table2"] = compare_table_ii(t2, args.policies, exp)
                failed += sum(r[pol]["failed"] for r in t2.values() for pol in args.policies)
            if "tuples" in args.parts:
                b = lab.host(clock_offset_s=2 * args.offset_s, rate="1gbit")
                svc_b = b.service(
                    *common.synthetic_camera_flags(["cam2"], args.fps, args.width, args.height, [0.0], args.jitter_ms),
                    "--slots",
                    str(args.slots),
                )
                both = stack.enter_context(
                    Client([svc_a.endpoint, svc_b.endpoint], timeout=args.timeout, keys=lab.client_keys)
                )
                watch.watch("A+B", both, svc_a.endpoint, a.clock_offset_ns)
                watch.watch("A+B", both, svc_b.endpoint, b.clock_offset_ns)
                common.wait_until_streaming(both.clients[1])
                result["tuples"] = two_host_tuples(
                    args, both, {"cam0": a.clock_offset_ns, "cam2": b.clock_offset_ns}, rng
                )
                result["targets"]["tuples"] = result["tuples"]["passed"]
                failed += result["tuples"]["failed"]
            if "size" in args.parts:
                result["size"] = sizes(args, a, remote, names)
                result["targets"]["size"] = result["size"]["targets"]
            failed += keep_asking(args, remote["raw"], names, watch, rng)
            watch.stop()
            result["clock"] = watch.report()
            result["clock_samples"] = watch.samples
            result["targets"]["clock"] = result["clock"]["target"]
            print()
            print_clock(result["clock"], args.minutes)
    except HostsUnavailable as exc:
        print(f"network: emulated hosts unavailable: {exc}", file=sys.stderr)
        return common.EXIT_FAILED
    except RuntimeError as exc:
        print(f"network: {exc}", file=sys.stderr)
        return common.EXIT_FAILED
    result["failed"] = failed
    result["duration_s"] = time.time() - started
    path = os.path.join(out, "network.json")
    common.write_json(path, result)
    print(f"\nfailed requests: {failed}; took {result['duration_s']:.0f} s; wrote {path}")
    if failed:
        return common.EXIT_FAILED
    if args.strict and not all(passed is True for passed in verdicts(result["targets"])):
        return common.EXIT_FAILED
    return common.EXIT_OK


def verdicts(targets: dict) -> list:
    """Every target's ``passed`` (True, False or None: not measured)."""
    flat = []
    for value in targets.values():
        for t in value if isinstance(value, list) else [value]:
            flat.append(t["passed"] if isinstance(t, dict) else t)
    return flat


if __name__ == "__main__":
    sys.exit(main())
