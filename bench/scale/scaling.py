"""Scaling: how request latency and throughput grow with cameras, frame size and clients, and
the highest frame rate 4 cameras sustain without losing a frame while requests are served.

Every section launches its own `fxis run` services (synthetic mono8 cameras, rings of --slots,
tcp loopback, free ports), one at a time, each stopped before the next. A "past tuple" is
client.tuple(at=time.monotonic_ns() - 150 ms): t* lies in the past, its frames are stored, so
nothing is waited for (the bench and the service share CLOCK_MONOTONIC on one host). Timed
requests each follow a random sleep U[0, --sleep-max-ms] ms.

{sections}
The cameras and size sections measure each transport of --paths; the clients and fps
sections use --load-path (network by default: the coordinator copies every frame). The
local fast path needs a Client that takes local=; without it the local rows are skipped
with a note.

Targets (PASS/FAIL lines): latency grows no worse than linearly with cameras; latency is flat
with idle clients (median with the most idle clients <= 1.25 x median with none);
--fps-cameras cameras at --target-fps with no loss while serving --request-hz tuple requests
per second (judged on the step at --target-fps, or the next one above; other failed steps
are named).

Writes scaling.json (settings, every service's status, every request) and scaling.png (one
panel per section) into --out, and the services' logs (scaling.SECTION.service.log).
Exit status: 0 when the run completed (whatever the targets say); 1 if a service did not
start or stream, or a request of the cameras, size or clients sections failed (in the fps
section a failed request fails its step instead), or with --strict if a target failed; 2 on
bad flags.

Each section is one module: cameras.py, size.py, clients.py,
fps.py; what they share is in timing.py.
"""

from __future__ import annotations

import argparse
import math
import os
import random
import sys
import textwrap
import time

if not __package__:  # run as a script (python bench/scale/scaling.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.scale import (
    cameras as scaling_cameras,
    clients as scaling_clients,
    fps as scaling_fps,
    size as scaling_size,
    timing as shared,
)
from bench.shared import common

# Each section's module: run(args, logs, rng) -> result; report(result, args); targets(result,
# args) -> [{target, passed, detail}]; PANELS, functions (ax, results, args) drawing a panel.
SECTIONS = {"cameras": scaling_cameras, "size": scaling_size, "clients": scaling_clients, "fps": scaling_fps}


def description() -> str:
    """This module's text with every section's own (its module's docstring) put in."""
    blocks = []
    for name, module in SECTIONS.items():
        text = textwrap.indent(module.__doc__.strip(), " " * 11)
        blocks.append(f"  {name:<8} " + text[11:])
    return __doc__.format(sections="\n".join(blocks) + "\n")


# ---- command line ----------------------------------------------------------------------------


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, description())
    p.add_argument(
        "--only",
        type=shared.name_list(tuple(SECTIONS)),
        default=",".join(SECTIONS),
        metavar="LIST",
        help=f"sections to run, comma-separated, of {','.join(SECTIONS)}",
    )
    common.add_pacing_args(
        p, "per point and transport (cameras, size, idle clients)", count=200, warmup=5, sleep_max_ms=10.0
    )
    p.add_argument(
        "--paths",
        type=shared.name_list(shared.PATHS),
        default=",".join(shared.PATHS),
        metavar="LIST",
        help='transports of the cameras and size sections: network (local="off"), '
        'local (local="require", the shared-memory fast path)',
    )
    p.add_argument(
        "--load-path",
        choices=shared.PATHS,
        default="network",
        help="transport of the clients of the clients and fps sections",
    )
    p.add_argument("--slots", type=common.positive_int, default=20, help="frames per camera ring")
    p.add_argument("--strict", action="store_true", help="exit with status 1 if a target failed")
    g = p.add_argument_group("cameras and size sections")
    g.add_argument(
        "--camera-counts",
        type=shared.positive_int_list,
        default="1,2,3,4,6,8",
        metavar="LIST",
        help="camera counts of the cameras section (1360x1024)",
    )
    g.add_argument(
        "--sizes",
        type=shared.size_list,
        default="640x480,1360x1024,2048x2048,4096x3072",
        metavar="LIST",
        help="frame sizes WxH of the size section (2 cameras)",
    )
    g.add_argument(
        "--low-fps", type=common.positive_float, default=10.0, help="frame rate of the cameras of these two sections"
    )
    g = p.add_argument_group("clients section")
    g.add_argument(
        "--idle-counts",
        type=shared.int_list,
        default="0,1,4,16,64",
        metavar="LIST",
        help="idle connected clients besides the one timing requests",
    )
    g.add_argument(
        "--active-counts",
        type=shared.positive_int_list,
        default="1,2,4,8,16,32,64",
        metavar="LIST",
        help="clients asking back to back at once",
    )
    g.add_argument(
        "--active-seconds", type=common.positive_float, default=4.0, help="how long the active clients ask, per count"
    )
    g.add_argument(
        "--processes", type=common.positive_int, default=4, help="worker processes the active clients are spread over"
    )
    g.add_argument(
        "--clients-fps",
        type=common.positive_float,
        default=20.0,
        help="frame rate of the 2 cameras of the clients section",
    )
    g = p.add_argument_group("fps section")
    g.add_argument(
        "--fps-steps",
        type=shared.float_list,
        default="50,75,100,125,150,200,250,300",
        metavar="LIST",
        help="frame rates per camera to step through",
    )
    g.add_argument("--seconds", type=common.positive_float, default=10.0, help="steady state per fps step")
    g.add_argument(
        "--warmup-seconds",
        type=common.nonnegative_float,
        default=3.0,
        help="before each step's steady state (the requests already run)",
    )
    g.add_argument("--fps-cameras", type=common.positive_int, default=4, help="cameras (1360x1024) of the fps section")
    g.add_argument(
        "--request-hz",
        type=common.positive_float,
        default=50.0,
        help="client.tuple() requests per second during a step",
    )
    g.add_argument(
        "--target-fps", type=common.positive_float, default=100.0, help="the frame rate the fps target asks for"
    )
    common.add_output_args(
        p.add_argument_group("output"),
        "folder for scaling.json, scaling.png and the service logs (files are overwritten)",
    )
    return p


# ---- report and figure ------------------------------------------------------------------------


def report(section: str, result: dict, args) -> None:
    if "error" in result:
        print(f"{section}: FAILED: {result['error']}")
    else:
        SECTIONS[section].report(result, args)
    print(flush=True)


def targets(results: dict, args) -> list[dict]:
    return [
        t
        for section, result in results.items()
        if "error" not in result
        for t in SECTIONS[section].targets(result, args)
    ]


def plot(results: dict, path: str, title: str, args) -> None:
    plt = common.pyplot()
    panels = [
        panel for section, result in results.items() if "error" not in result for panel in SECTIONS[section].PANELS
    ]
    if not panels:
        return
    cols = 2 if len(panels) <= 4 else 3
    rows = math.ceil(len(panels) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.5 * cols, 4.6 * rows), squeeze=False)
    for ax, panel in zip(axes.flat, panels):
        panel(ax, results, args)
        ax.grid(True, alpha=0.3)
    for ax in list(axes.flat)[len(panels) :]:
        ax.set_visible(False)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ---- main ------------------------------------------------------------------------------------


def request_failures(results: dict) -> int:
    """Failed requests of the cameras, size and clients sections."""
    summaries = []
    for key in ("cameras", "size"):
        for p in results.get(key, {}).get("points", []):
            summaries += [m["summary"] for m in p["paths"].values()]
    clients = results.get("clients", {})
    summaries += [p["summary"] for p in clients.get("idle", []) + clients.get("active", [])]
    return sum(s["failed"] for s in summaries)


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = common.parse_args(p, argv)
    if isinstance(args, int):
        return args
    if args.load_path == "local" and not shared.local_supported():
        return common.usage_error(p, "--load-path local needs a Client with the local= keyword")
    out = common.ensure_dir(args.out)
    rng = random.Random(args.seed)
    logs = shared.Logs(out)
    host = common.host_info()  # before any service starts: the code it runs
    started = time.time()
    print(common.code_line(host["code"]))
    print(
        f"scaling: sections {','.join(args.only)}; {os.cpu_count()} CPUs; transports "
        f"{','.join(shared.usable_paths(args.paths))}; timeout {args.timeout:g} s",
        flush=True,
    )
    if "local" in args.paths and not shared.local_supported():
        print(
            "note: this Client has no local= keyword (the shared-memory fast path); "
            "the local transport is skipped, every request goes over the network path",
            flush=True,
        )
    results: dict = {}
    json_path, png_path = os.path.join(out, "scaling.json"), os.path.join(out, "scaling.png")
    for section in args.only:
        logs.start(section)
        try:
            results[section] = SECTIONS[section].run(args, logs, rng)
        except (RuntimeError, OSError, EOFError, *common.REQUEST_ERRORS) as exc:
            results[section] = {"error": f"{type(exc).__name__}: {exc}"}
        report(section, results[section], args)
        document = {
            **common.run_record("scaling", started, argv, args),
            "host": host,
            "local_supported": shared.local_supported(),
            "clock": "CLOCK_MONOTONIC ns; t_send is the bench's time.monotonic_ns()",
            "results": results,
        }
        common.write_json(json_path, document)  # after every section: a crash keeps what was measured

    checks = targets(results, args)
    document["targets"] = checks
    common.write_json(json_path, document)
    print("targets:" if checks else "targets: none (they belong to the cameras, clients and fps sections)")
    for t in checks:
        verdict = {True: "PASS", False: "FAIL", None: "n/a"}[t["passed"]]
        print(f"  {verdict}  {t['target']}: {t['detail']}")
    failed = request_failures(results)
    broken = [s for s, r in results.items() if "error" in r]
    print(
        f"failed requests (cameras, size, clients): {failed}; sections that could not run: "
        f"{', '.join(broken) or 'none'}"
    )
    plot(results, png_path, f"scaling ({os.cpu_count()} CPUs, {','.join(shared.usable_paths(args.paths))})", args)
    print(f"wrote {json_path} and {png_path}")
    if failed or broken:
        return common.EXIT_FAILED
    if args.strict and any(t["passed"] is not True for t in checks):
        return common.EXIT_FAILED
    return common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
