"""Does `fxis record --codec h264` keep up with the cameras, and do the rings notice it?

Per --setups entry CAMERASxFPS (default 2x30 and 4x15): launches a service with that many
synthetic mono8 cameras of --size (1360x1024), waits until they stream, then runs the real
recorder, `fxis record --codec h264 --seconds S` (default encoder, CRF, preset, GOP), into a
temp folder, as a process of its own, and measures:
  the recorder   frames recorded, missed (the ring came round first) and skipped by its encoder
                 (it fell behind; must be 0) per camera, from its summary; its CPU a frame,
                 steady (from /proc, over the recording less --warmup at the start and 1 s at
                 the end) and in all (getrusage of the child: start-up and flush included);
  the ring's view the cameras' frames_dropped, frames stored (the rate they kept) and the
                 coordinator's torn reads per camera and events_dropped, from the service's
                 status before and after the recording: every count but stored must not grow;
  the host       its idle CPU over the same time and the load average, since the machine may be
                 shared.
The synthetic scene is a sliding gradient, far easier to encode than a real one (bench/video/
sizes.py measures a realistic scene's CPU a frame with the same encoder, in one process).

Prints a table per setup and writes video_keepup.json into --out. Exit status 0 when every
setup ran (whatever it measured); 1 if the service or the recorder failed; 2 on bad flags.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time

if not __package__:  # run as a script (python bench/video/keepup.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common
from bench.shared.cpu import IDLE, cpu_percent, cpu_sample

RECORDER = "recorder"
END_MARGIN_S = 1.0  # the steady sample ends this long before the recorder's own end


def setup_list(text: str) -> list[tuple[int, float]]:
    try:
        setups = [(int(c), float(f)) for c, f in (part.lower().split("x") for part in text.split(",") if part.strip())]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected CAMERASxFPS[,...], got {text!r}") from None
    if not setups or any(c < 1 or f <= 0 for c, f in setups):
        raise argparse.ArgumentTypeError(f"expected CAMERASxFPS[,...] of positive numbers, got {text!r}")
    return setups


def frame_size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    return width, height


def parser():
    p = common.parser_for(__file__, __doc__)
    p.add_argument("--setups", type=setup_list, default=setup_list("2x30,4x15"), help="CAMERASxFPS, comma-separated")
    p.add_argument("--size", type=frame_size, default="1360x1024", metavar="WxH", help="image size of the cameras")
    p.add_argument("--seconds", type=common.positive_float, default=20.0, help="seconds each recording runs")
    p.add_argument("--warmup", type=common.nonnegative_float, default=3.0, help="seconds of the recording not measured")
    common.add_service_args(p, "its cameras are then recorded as they are, once (--setups is ignored)")
    return p


def ring_counts(status: dict) -> dict:
    """What the rings and the coordinator count, per camera and in all."""
    cams = status["cameras"]
    return {
        "cameras": {
            name: {k: c.get(k) or 0 for k in ("frames_dropped", "frames_stored", "torn_reads")}
            for name, c in cams.items()
        },
        "events_dropped": status.get("events_dropped") or 0,
    }


def grown(before: dict, after: dict) -> dict:
    out = {
        name: {k: after["cameras"][name][k] - v for k, v in counts.items()}
        for name, counts in before["cameras"].items()
        if name in after["cameras"]
    }
    return {"cameras": out, "events_dropped": after["events_dropped"] - before["events_dropped"]}


def parse_summary(text: str, cameras: list[str]) -> dict:
    """frames, missed, dropped by camera and skipped per camera, from `fxis record`'s summary."""
    per = {}
    for cam in cameras:
        row = re.search(rf"^{re.escape(cam)}\s+\S+\s+(\d+)\s+(\S+)\s+(\S+)\s*$", text, re.M)
        skipped = re.search(rf"^{re.escape(cam)}: the encoder fell behind and skipped (\d+) frames", text, re.M)
        per[cam] = {
            "frames": int(row.group(1)) if row else None,
            "missed": row.group(2) if row else None,
            "dropped_by_camera": row.group(3) if row else None,
            "skipped": int(skipped.group(1)) if skipped else 0,
        }
    return per


def record(endpoint: str, cameras: list[str], args, scratch: str) -> dict:
    """One `fxis record --codec h264` run: its summary, CPU and what the host did meanwhile."""
    command = [sys.executable, "-m", "fxis_shm.cli", "record", "--endpoint", endpoint]
    command += ["--out", os.path.join(scratch, "bag"), "--codec", "h264", "--seconds", f"{args.seconds:g}"]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(args.warmup)
        t0, before = time.monotonic(), cpu_sample({RECORDER: proc.pid})
        time.sleep(max(0.5, args.seconds - args.warmup - END_MARGIN_S))
        steady = cpu_percent(before, cpu_sample({RECORDER: proc.pid}), time.monotonic() - t0)
        steady_s = time.monotonic() - t0
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        out, err = proc.stdout.read(), proc.stderr.read()  # (small: a summary and a few lines)
    finally:
        if proc.returncode is None:
            proc.kill()
            proc.wait()
        for pipe in (proc.stdout, proc.stderr):
            pipe.close()
    if proc.returncode != 0:
        raise RuntimeError(f"fxis record failed (exit {proc.returncode}): {err.strip()}")
    return {
        "command": command,
        "steady_cpu_percent": steady[RECORDER],
        "steady_s": steady_s,
        "host_idle_percent": steady[IDLE],
        "total_cpu_s": usage.ru_utime + usage.ru_stime,
        "summary": parse_summary(out, cameras),
        "stdout": out,
        "stderr": err,
    }


def run_setup(endpoint: str | None, n_cams: int, fps: float, size: tuple[int, int], args, out: str) -> dict:
    names = [f"cam{i}" for i in range(n_cams)]
    run_args = common.synthetic_camera_flags(names, fps, *size)
    log = os.path.join(out, f"video_keepup.{n_cams}x{fps:g}.service.log")
    with common.service(endpoint, run_args, log, args.timeout) as (client, info):
        status = common.wait_until_streaming(client)
        cameras = list(status["cameras"])
        before = ring_counts(status)
        load = os.getloadavg()
        with tempfile.TemporaryDirectory(prefix="video_keepup.") as scratch:
            rec = record(info["endpoint"], cameras, args, scratch)
        after = ring_counts(client.status())
        fps_set = {name: c.get("fps") for name, c in status["cameras"].items()}
    return {"cameras": cameras, "fps": fps_set, "load_average": load, "recorder": rec, "rings": grown(before, after)}


def report(name: str, result: dict, args) -> str:
    rec, rings = result["recorder"], result["rings"]
    total_fps = sum(f or 0 for f in result["fps"].values())
    frames = sum(c["frames"] or 0 for c in rec["summary"].values())
    steady_ms = rec["steady_cpu_percent"] / 100 / total_fps * 1e3 if total_fps else None
    rows = []
    for cam in result["cameras"]:
        s, r = rec["summary"][cam], rings["cameras"].get(cam, {})
        rows.append(
            [cam, s["frames"], s["missed"], s["skipped"], s["dropped_by_camera"],
             r.get("frames_dropped"), r.get("torn_reads"), r.get("frames_stored")]
        )  # fmt: skip
    load = result["load_average"]
    head = ["camera", "recorded", "missed", "skipped", "dropped (rec)", "dropped (ring)", "torn reads", "stored"]
    lines = [
        common.table(head, rows, title=f"{name}: fxis record --codec h264 --seconds {args.seconds:g}"),
        f"recorder CPU: {rec['steady_cpu_percent']:.0f} % of a core steady ({rec['steady_s']:.1f} s) = "
        f"{common.fmt(steady_ms)} ms a frame; {rec['total_cpu_s']:.1f} s in all for {frames} frames = "
        f"{rec['total_cpu_s'] / max(1, frames) * 1e3:.2f} ms a frame (start-up and flush included)",
        f"coordinator events_dropped: {rings['events_dropped']}; host idle {rec['host_idle_percent']:.0f} % "
        f"(of {os.cpu_count() * 100} %); load average at start {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}",
        f"recorder said: {rec['stderr'].strip().splitlines()[0] if rec['stderr'].strip() else '-'}",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = common.parse_args(p, argv)
    if isinstance(args, int):
        return args
    width, height = args.size
    if args.warmup + END_MARGIN_S >= args.seconds:
        return common.usage_error(p, f"--seconds must exceed --warmup + {END_MARGIN_S:g}")
    setups = [(0, 0.0)] if args.endpoint else args.setups
    out, results = common.ensure_dir(args.out), {}
    try:
        for n_cams, fps in setups:
            name = "the running service" if args.endpoint else f"{n_cams} x {width}x{height} at {fps:g} fps"
            print(f"{name}: recording {args.seconds:g} s ...", file=sys.stderr, flush=True)
            results[name] = run_setup(args.endpoint, n_cams, fps, args.size, args, out)
            print(report(name, results[name], args) + "\n", flush=True)
    except (RuntimeError, common.FxisError) as exc:
        print(f"keepup.py: {common.describe_error(exc)}", file=sys.stderr)
        return common.EXIT_FAILED
    print(common.code_line(common.code_version()))
    common.write_json(
        os.path.join(out, "video_keepup.json"),
        {"settings": vars(args), "host": common.host_info(), "results": results},
    )
    return common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
