"""``fxis sync-report ENDPOINT...``: are the cameras in sync? N seconds of joint tuples from one
service or a cell of several (the caller's clock across hosts), judged by librealsense's criteria
(fxis_shm.core.syncstats), printed, and written as JSON and a PNG plot. Exit 0 on PASS,
exitcodes.SYNC_FAILED on FAIL (docs/cli.md, docs/sync.md "Proving sync")."""

from __future__ import annotations

import json
import os

from fxis_shm.cli import exitcodes
from fxis_shm.cli.options import add_client_options, client_for, duration_seconds, milliseconds, percent, rate_hz
from fxis_shm.cli.query import ptp_text
from fxis_shm.cli.stopsignals import as_interrupts, interrupted
from fxis_shm.cli.table import aligned
from fxis_shm.core import syncstats
from fxis_shm.errors import InvalidArgument

FALLBACK_RATE_HZ = 10.0  # when no camera says its rate


def sync_report_command(args) -> int:
    from fxis_shm.client.syncsampler import planned_slots, take

    for path, flag in ((args.json, "--json"), (args.plot, "--plot")):
        if path is not None:
            _check_writable(path, flag)
    if args.plot is not None and not args.plot.lower().endswith(".png"):
        raise InvalidArgument(f"--plot {args.plot}: the plot is a PNG; give a path ending in .png")
    if args.rate is not None:  # the plan's size, before a service is asked (else once its rate is known)
        planned_slots(args.seconds, args.rate)
    thresholds = syncstats.Thresholds(args.threshold_ms, args.max_p95_ms, args.min_synced_pct, args.max_dropped_pct)
    endpoints = [*args.endpoints, *([args.endpoint] if args.endpoint else [])] if args.endpoints else None
    with as_interrupts(), client_for(args, endpoints) as client:
        status = client.status()
        cameras = chosen_cameras(args.cameras, status["cameras"])
        set_periods = {n: 1e9 / status["cameras"][n]["fps"] for n in cameras if status["cameras"][n].get("fps")}
        rate = args.rate or (1e9 / max(set_periods.values()) if set_periods else FALLBACK_RATE_HZ)
        slots = planned_slots(args.seconds, rate)  # before the schedule: a plan of 10^9 is refused
        # cameras that capture only on a trigger: asked to capture at each t_k, judged on those moments
        on_request = [n for n in cameras if status["cameras"][n].get("trigger") == "software"]
        periods = {n: p for n, p in set_periods.items() if n not in on_request}
        where = list(getattr(client, "endpoints", None) or [client.endpoint])
        asked = f"; {', '.join(on_request)} capture on request: each t_k asked as a capture at T" if on_request else ""
        print(
            f"sync report: {len(cameras)} camera(s) ({', '.join(cameras)}) of {', '.join(where)}: "
            f"{slots} tuples asked at {rate:g} Hz over {args.seconds:g} s, "
            f"times in this host's clock{asked}",
            flush=True,  # a caller watching the output knows the schedule has begun
        )
        taken = take(client, cameras, args.seconds, rate, capture=bool(on_request))
    figures = syncstats.figures(taken.samples, thresholds, periods, on_request)
    ptp = {n: status["cameras"][n].get("ptp") for n in cameras}
    services = {n: status["cameras"][n].get("service") or where[0] for n in cameras}
    print("\n".join(report_lines(figures, thresholds, ptp, services, taken.errors)))
    if args.json is not None:
        _write_json(args.json, args, rate, thresholds, figures, ptp, services, taken)
    if args.plot is not None:
        from fxis_shm.viewers import syncplot

        title = f"{', '.join(cameras)}: {figures.slots} tuples at {rate:g} Hz"
        syncplot.write(args.plot, syncplot.draw(taken.samples, figures, thresholds.threshold_ms, title))
    if taken.interrupted:
        return interrupted("sync-report", f"interrupted: the figures above are of the first {figures.slots} slots")
    return exitcodes.DONE if figures.passed else exitcodes.SYNC_FAILED


def chosen_cameras(names: str | None, known: dict) -> list[str]:
    if not names:
        return list(known)
    chosen = [n.strip() for n in names.split(",") if n.strip()]
    unknown = [n for n in chosen if n not in known]
    if unknown:
        raise InvalidArgument(f"--cameras: unknown camera(s) {unknown}; the service(s) have {sorted(known)}")
    return chosen


def _check_writable(path: str, flag: str) -> None:
    """A file the report will write: its folder must exist and take files (checked before the run)."""
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path) or not os.path.isdir(folder) or not os.access(folder, os.W_OK):
        raise InvalidArgument(f"{flag} {path}: cannot write a file there; give a file in a folder this user can write")


def report_lines(
    figures: syncstats.Figures,
    thresholds: syncstats.Thresholds,
    ptp: dict[str, dict | None],
    services: dict[str, str | None],
    errors: dict[str, int],
) -> list[str]:
    gap = figures.gap_ms
    lines = [
        (
            f"gap (skew)  p50 {gap['p50']:.3f} ms  p95 {gap['p95']:.3f} ms  p99 {gap['p99']:.3f} ms  "
            f"max {gap['max']:.3f} ms  mean {gap['mean']:.3f} ms  (of {figures.complete} complete tuples)"
            if gap
            else "gap (skew)  - (no complete tuple)"
        ),
        f"synced      {figures.synced_pct:.1f} % of {figures.slots} tuples within {thresholds.threshold_ms:g} ms",
        f"dropped     {figures.dropped_pct:.1f} % of {figures.slots} tuples (a camera missing, or a frame id "
        "repeated or skipped against its period)",
    ]
    rows = [["camera", "service", "period_ms", "missing", "repeated", "skipped", *syncstats.CAPTURE_METHODS,
             "residual p50/p99 ms", "ptp"]]  # fmt: skip
    for name, cam in figures.cameras.items():
        residual = f"{cam.residual_ms['p50']:.3f}/{cam.residual_ms['p99']:.3f}" if cam.residual_ms else "-"
        period = "on request" if cam.on_request else "-" if cam.period_ms is None else f"{cam.period_ms:g}"
        cells = [name, services.get(name) or "-", period]
        cells += [str(cam.missing), str(cam.repeated), str(cam.skipped)]
        cells += [str(cam.captures[m]) for m in syncstats.CAPTURE_METHODS] + [residual, ptp_text(ptp.get(name))]
        rows.append(cells)
    lines += aligned(rows)
    lines += [f"  no tuple ({count}x): {why}" for why, count in errors.items()]
    lines.append(f"{'PASS' if figures.passed else 'FAIL'}: {'; '.join(map(str, figures.checks))}")
    return lines


def _write_json(path, args, rate, thresholds, figures, ptp, services, taken) -> None:
    gaps = syncstats.gaps_ns(taken.samples)
    document = {
        "seconds": args.seconds,
        "rate_hz": rate,
        "services": services,
        "thresholds": vars(thresholds),
        **figures.as_dict(),
        "ptp": ptp,
        "no_tuple": dict(taken.errors),
        "interrupted": taken.interrupted,
        # each slot: t_k (this host's clock, ns) and its tuple's gap (ns; null when not complete)
        "tuples": [{"t": int(t), "gap_ns": None if g != g else int(g)} for t, g in zip(taken.samples.slots, gaps)],
    }
    with open(path, "w") as out:
        json.dump(document, out, indent=2)


def add_parser(sub) -> None:
    report = sub.add_parser(
        "sync-report",
        help="are the cameras in sync? librealsense's criteria over N seconds of joint tuples, PASS or FAIL",
        description="Ask one service, or a cell of several (ENDPOINT...), for a joint tuple every 1/rate s for "
        "--seconds, and print the tuples' gap (skew) p50/p95/p99, the share within --threshold-ms, the share "
        "dropped (a camera missing, a frame id repeated or skipped), and per camera the capture methods, "
        "residuals and PTP state; then PASS or FAIL against the limits (librealsense's by default: p95 gap "
        f"<= 3 ms, >= 95 % synced, <= 5 % dropped). Exit status 0 on PASS, {exitcodes.SYNC_FAILED} on FAIL.",
    )
    report.add_argument("endpoints", nargs="*", metavar="ENDPOINT", help="services (default: --endpoint's)")
    add_client_options(report)
    report.add_argument("--seconds", type=duration_seconds, default=10.0, help="how long (default 10)")
    report.add_argument("--rate", type=rate_hz, metavar="HZ", help="tuples per second (default: the "
                        "slowest camera's rate)")  # fmt: skip
    report.add_argument("--cameras", metavar="A,B", help="comma-separated cameras (default all)")
    report.add_argument("--threshold-ms", type=milliseconds, default=syncstats.DEFAULT_THRESHOLD_MS, metavar="X",
                        help="a tuple is synced when its gap is at most this (default 3)")  # fmt: skip
    report.add_argument("--max-p95-ms", type=milliseconds, default=syncstats.DEFAULT_MAX_P95_MS, metavar="X",
                        help="PASS needs the 95th percentile gap at most this (default 3)")  # fmt: skip
    report.add_argument("--min-synced-pct", type=percent, default=syncstats.DEFAULT_MIN_SYNCED_PCT, metavar="P",
                        help="PASS needs at least this %% of tuples synced (default 95)")  # fmt: skip
    report.add_argument("--max-dropped-pct", type=percent, default=syncstats.DEFAULT_MAX_DROPPED_PCT, metavar="P",
                        help="PASS needs at most this %% of tuples dropped (default 5)")  # fmt: skip
    report.add_argument("--json", metavar="FILE", help="write the figures, and each tuple's gap, as JSON")
    report.add_argument("--plot", metavar="FILE.png", help="write a plot: the gap over time and its histogram")
    report.set_defaults(func=sync_report_command)
