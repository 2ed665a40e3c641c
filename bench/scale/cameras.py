"""--camera-counts services (1,2,3,4,6,8 cameras, 1360x1024 at --low-fps 10 fps, so
that rendering does not saturate 2 cores); -n past tuples per transport (--paths):
network = Client(local="off"), frames copied through the coordinator's socket;
local = Client(local="require"), the shared-memory fast path. Reports median and
p99 round trip, ms per camera, the service's own time (timing sent - received),
and whether the latency grows no worse than linearly: latency(n) / latency(1) <= n
(times 1.2 for noise) at every n > 1; the fitted exponent b of latency ~ n^b is
shown too.
"""

from __future__ import annotations

import random

import numpy as np

from bench.scale import timing as shared
from bench.shared import common

LINEAR_MARGIN = 1.2  # latency(n) / latency(1) may exceed n by this factor (noise)


def run(args, logs: shared.Logs, rng: random.Random) -> dict:
    points = []
    for n in args.camera_counts:
        run_args = shared.camera_args(n, args.low_fps, 1360, 1024, args.slots)
        with logs.service("cameras", run_args, args.timeout) as (svc, status):
            points.append(
                {"cameras": n, "status": status, "paths": shared.measure_paths(args, svc.endpoint, rng, f"cameras {n}")}
            )
    return {"points": points, "growth": {path: growth(points, path) for path in shared.usable_paths(args.paths)}}


def growth(points: list[dict], path: str) -> dict:
    """Is median latency(n) / latency(1) <= n (x LINEAR_MARGIN) everywhere? And the exponent b."""
    pairs = [
        (p["cameras"], p["paths"][path]["summary"]["rtt_ms"]["median"])
        for p in points
        if path in p["paths"] and p["paths"][path]["summary"]["rtt_ms"]["median"]
    ]
    base = dict(pairs).get(1)
    if base is None or len(pairs) < 2:
        return {"passed": None, "why": "needs 1 camera and another count"}
    ratios = {n: m / base for n, m in pairs}
    worst_n = max((n for n in ratios if n > 1), key=lambda n: ratios[n] / n)
    exponent = float(np.polyfit(np.log([n for n, _ in pairs]), np.log([m for _, m in pairs]), 1)[0])
    return {
        "ratios": ratios,
        "worst_n": worst_n,
        "worst_ratio_per_n": ratios[worst_n] / worst_n,
        "exponent": exponent,
        "passed": ratios[worst_n] / worst_n <= LINEAR_MARGIN,
    }


def report(result: dict, args) -> None:
    rows = []
    for p in result["points"]:
        for path, m in p["paths"].items():
            s = m["summary"]
            med = s["rtt_ms"]["median"]
            rows.append(
                [
                    f"{p['cameras']} cameras  {path}",
                    s["requests"],
                    s["failed"],
                    med,
                    s["rtt_ms"]["p99"],
                    med / p["cameras"] if med is not None else None,
                    s["service_ms"]["median"],
                    (s["bytes"] or 0) / shared.MB,
                    result["growth"][path].get("ratios", {}).get(p["cameras"]),
                ]
            )
    print(
        common.table(
            [
                "cameras  path",
                "n",
                "failed",
                "median ms",
                "p99 ms",
                "ms/camera",
                "service ms",
                "MB/tuple",
                "x latency(1)",
            ],
            rows,
            digits=2,
            title="cameras: past tuples, 1360x1024 mono8 cameras",
        )
    )
    print(shared.sanity_line(result["points"]))


def targets(result: dict, args) -> list[dict]:
    out = []
    for path, g in result["growth"].items():
        detail = (
            f"worst latency(n)/latency(1) = {g['ratios'][g['worst_n']]:.2f} at n={g['worst_n']} "
            f"(= {g['worst_ratio_per_n']:.2f} x n, limit {LINEAR_MARGIN:g} x n); fitted exponent "
            f"b = {g['exponent']:.2f}"
            if "ratios" in g
            else g["why"]
        )
        out.append(
            {
                "target": f"latency grows no worse than linearly with cameras ({path})",
                "passed": g["passed"],
                "detail": detail,
            }
        )
    return out


def plot(ax, results, args) -> None:
    points = results["cameras"]["points"]
    for path in shared.usable_paths(args.paths):
        n = [p["cameras"] for p in points]
        med = [p["paths"][path]["summary"]["rtt_ms"]["median"] for p in points]
        p99 = [p["paths"][path]["summary"]["rtt_ms"]["p99"] for p in points]
        (line,) = ax.plot(n, med, "o-", label=f"{path} median")
        ax.plot(n, p99, "^:", color=line.get_color(), label=f"{path} p99")
        base = dict(zip(n, med)).get(1)
        if base:
            ax.plot(n, [base * k for k in n], "--", color=line.get_color(), alpha=0.4, label=f"{path}: latency(1) x n")
    ax.set_xlabel("cameras (1360x1024 mono8)")
    ax.set_ylabel("past tuple round trip, ms")
    ax.set_title("cameras")
    ax.legend(fontsize=7)


PANELS = [plot]
