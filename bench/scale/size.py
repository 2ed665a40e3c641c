"""2 cameras at --low-fps, --sizes 640x480 .. 4096x3072: the same measurement, with
MB per tuple (1 MB = 10^6 bytes) and MB/s = MB per tuple / median round trip (what
one client asking back to back would get).
"""

from __future__ import annotations

import random

from bench.scale import timing as shared
from bench.shared import common


def run(args, logs: shared.Logs, rng: random.Random) -> dict:
    points = []
    for width, height in args.sizes:
        run_args = shared.camera_args(2, args.low_fps, width, height, args.slots)
        with logs.service("size", run_args, args.timeout) as (svc, status):
            points.append(
                {
                    "width": width,
                    "height": height,
                    "status": status,
                    "paths": shared.measure_paths(args, svc.endpoint, rng, f"size {width}x{height}"),
                }
            )
    return {"points": points}


def throughput_mb_s(summary: dict) -> float | None:
    med = summary["rtt_ms"]["median"]
    return summary["bytes"] / shared.MB / (med / 1000) if med and summary["bytes"] else None


def report(result: dict, args) -> None:
    rows = []
    for p in result["points"]:
        for path, m in p["paths"].items():
            s = m["summary"]
            rows.append(
                [
                    f"{p['width']}x{p['height']}  {path}",
                    s["requests"],
                    s["failed"],
                    (s["bytes"] or 0) / shared.MB,
                    s["rtt_ms"]["median"],
                    s["rtt_ms"]["p99"],
                    s["service_ms"]["median"],
                    throughput_mb_s(s),
                ]
            )
    print(
        common.table(
            ["size  path", "n", "failed", "MB/tuple", "median ms", "p99 ms", "service ms", "MB/s"],
            rows,
            digits=2,
            title="size: past tuples of 2 mono8 cameras",
        )
    )
    print(shared.sanity_line(result["points"]))


def targets(result: dict, args) -> list[dict]:
    return []  # a table to read, no target


def plot(ax, results, args) -> None:
    points = results["size"]["points"]
    for path in shared.usable_paths(args.paths):
        x = [(p["paths"][path]["summary"]["bytes"] or 0) / shared.MB for p in points]
        y = [p["paths"][path]["summary"]["rtt_ms"]["median"] for p in points]
        ax.plot(x, y, "o-", label=f"{path} median")
        for p, xi, yi in zip(points, x, y):
            mbs = throughput_mb_s(p["paths"][path]["summary"])
            ax.annotate(
                f"{p['width']}x{p['height']}\n{common.fmt(mbs, 0)} MB/s",
                (xi, yi),
                fontsize=6,
                textcoords="offset points",
                xytext=(4, -10),
            )
    ax.set_xscale("log")
    ax.set_yscale("log")
    shared.plain_numbers(ax.xaxis, ax.yaxis)
    ax.set_xlabel("MB per tuple (2 cameras, log)")
    ax.set_ylabel("past tuple round trip, ms (log)")
    ax.set_title("frame size")
    ax.legend(fontsize=7)


PANELS = [plot]
