"""bench/network/remote.py's part table2: the paper's Table II for one host, remote raw and remote
JPEG, in paired rounds (every configuration calls at the same phase of its cameras' frame
period), and the remote means against the one host's."""

from __future__ import annotations

import math
import random
import statistics
import time

from bench.latency import experiment as paper
from bench.shared import common
from fxis_shm import Client

TABLE_II_TOLERANCE_MS = 0.5
ANCHOR_FRAMES = 10  # consecutive frames that fix a camera's phase (jitter averages out)
SPIN_MS = 2.0  # the end of each sleep is spent awake, so that calls come at their phase
PHASE_TOLERANCE_MS = 1.0  # a round counts in the comparison if every call came this close to it


def camera_anchor(client: Client, exp) -> int:
    """The phase of the first camera's frame times in the caller's clock, ns mod the period:
    the mean of (t_capture - frames since the first x period) over consecutive frames."""
    common.wait_until_streaming(client, min_frames=ANCHOR_FRAMES + 1)  # a service just started holds fewer
    frames = client.sequence("consecutive", camera=exp.names[0], count=ANCHOR_FRAMES)
    first = frames[0].frame_id
    return round(statistics.mean(f.t_capture - (f.frame_id - first) * exp.period_ns for f in frames)) % exp.period_ns


def paired_run(args, configs: dict[str, Client], exp, kinds_of: dict, rng: random.Random) -> list[dict]:
    """The paper's requests (bench/latency/experiment.py's measure) in rounds: a round draws one
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
