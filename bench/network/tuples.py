"""bench/network/remote.py's part tuples: tuples of a camera on host A and one on host B through one
client, their true skew (from the services' stamps and the exact offsets) against the least
the cameras allow."""

from __future__ import annotations

import random

from bench.latency import experiment as paper
from bench.shared import common
from fxis_shm import Client

TUPLE_TARGET_REQUESTS = 1000


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
