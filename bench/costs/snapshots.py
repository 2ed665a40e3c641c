"""Snapshot cost: what keeping the seconds around an event costs the service.

Launches a service of --cameras synthetic cameras (--width x --height at --fps, --history
seconds of rings) and measures, over each stage, the CPU of every process of the service
(% of one core, /proc) and the frames the cameras stored and dropped:

  idle       the service alone, --seconds long
  snapshot   one ``Client.snapshot(before=--before, after=--after)`` into a bag under --out,
             from this process (its CPU is the "bench" column), measured from its call to
             its return

Prints a table and what the snapshot kept (frames per camera, missing ids), writes
snapshot_cost.json into --out. Exit status 0, 1 if a frame of the window is missing.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import time

if not __package__:  # run as a script (python bench/costs/snapshots.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common, cpu


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    p.add_argument("--cameras", type=common.positive_int, default=4, help="synthetic cameras")
    p.add_argument("--fps", type=common.positive_float, default=30.0, help="their frame rate")
    common.add_frame_size_args(p, 1360, 1024)
    p.add_argument("--history", type=common.positive_float, default=3.0, help="seconds each ring holds")
    p.add_argument("--before", type=common.nonnegative_float, default=2.0, help="the snapshot's seconds before t")
    p.add_argument("--after", type=common.nonnegative_float, default=1.0, help="and after t")
    p.add_argument("--seconds", type=common.positive_float, default=5.0, help="the idle stage's length")
    common.add_output_args(p)
    return p


def measure(client, procs: dict[str, int], action) -> tuple[dict, float, dict]:
    """CPU % per process and the cameras' stored/dropped frames over ``action()``."""
    before, cams0, t0 = cpu.cpu_sample(procs), client.status()["cameras"], time.monotonic()
    result = action()
    after, cams1, seconds = cpu.cpu_sample(procs), client.status()["cameras"], time.monotonic() - t0
    frames = {
        n: {
            "fps": (cams1[n]["frames_stored"] - c["frames_stored"]) / seconds,
            "dropped": cams1[n]["frames_dropped"] - c["frames_dropped"],
        }
        for n, c in cams0.items()
    }
    return cpu.cpu_percent(before, after, seconds), seconds, {"frames": frames, "result": result}


def main(argv: list[str] | None = None) -> int:
    args = common.parse_args(parser(), argv)
    if isinstance(args, int):
        return args
    out = common.ensure_dir(args.out)
    cams = [f"cam{i}" for i in range(args.cameras)]
    run_args = common.synthetic_camera_flags(cams, args.fps, args.width, args.height) + [
        "--history",
        f"{args.history:g}",
    ]
    bag = os.path.join(out, "snapshot_cost.bag")
    shutil.rmtree(bag, ignore_errors=True)
    with common.service(None, run_args, os.path.join(out, "snapshot_cost.log"), args.timeout) as (client, _):
        status = common.wait_until_streaming(client)
        time.sleep(args.history)  # rings full: the window's past is all there
        procs = cpu.service_processes(client.status(), status["supervisor"]["pid"])
        stages = {
            "idle": measure(client, procs, lambda: time.sleep(args.seconds)),
            "snapshot": measure(client, procs, lambda: client.snapshot(before=args.before, after=args.after, out=bag)),
        }
    names = [n for n in stages["idle"][0] if not n.startswith("camera:") and n != cpu.IDLE]
    rows = []
    for stage, (percent, seconds, extra) in stages.items():
        cameras = sum(v for n, v in percent.items() if n.startswith("camera:") and v is not None)
        frames = extra["frames"]
        rows.append(
            [stage, seconds]
            + [percent.get(n) for n in names]
            + [cameras, min(f["fps"] for f in frames.values()), sum(f["dropped"] for f in frames.values())]
        )
    print(
        f"snapshot_cost: {common.code_line(common.code_version())}; {args.cameras} camera(s) "
        f"{args.width}x{args.height} at {args.fps:g} fps, history {args.history:g} s; "
        f"snapshot before {args.before:g} s, after {args.after:g} s"
    )
    print(common.table(["stage", "seconds"] + names + ["cameras", "cam fps min", "dropped"], rows, digits=1))
    kept = stages["snapshot"][2]["result"]["cameras"]
    for name, k in kept.items():
        print(
            f"  {name}: {k['frames']} frames kept, missing {k['missing'] or 'none'}, "
            f"gone before {k['gone_before_ms']} ms"
        )
    print(f"  bag: {common.fmt(sum(f.stat().st_size for f in os.scandir(bag)) / 1e6, 0)} MB in {bag}")
    common.write_json(
        os.path.join(out, "snapshot_cost.json"), {"settings": vars(args), "stages": stages, "host": common.host_info()}
    )
    return common.EXIT_FAILED if any(k["missing"] for k in kept.values()) else common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
