"""Two emulated GigE Vision cameras through the aravis backend: is every frame stored, and how
long from a frame's arrival to its being stored?

Starts two GigE Vision camera emulators (arv-fake-gv-camera-0.8, on 127.0.0.1 and 127.0.0.2;
the second address is added to lo for the run if missing, which needs root) and measures two
runs of --seconds each, each with its own `fxis run` service of two aravis cameras (default
640x480 Mono8 at 20 fps, timestamp=host or --timestamp device, rings of --slots):

  no hook      frames stored as they arrive;
  hook         every frame first goes through a processing hook of known cost
               (process=slow_hooks:sleep_10ms, bench/cameras/slow_hooks.py; bench/ is put on the camera
               workers' PYTHONPATH).

Every --poll seconds the bench fetches each camera's new frames with a "range" sequence
request (frame ids, t_capture, t_stored: the numbers a client sees) and reads the ring's slot
table on this host for each frame's t_available (the replies do not carry it).

Per camera and run:
  delivered      frames the camera sent in the run: the span of its frame ids (the camera's own
                 counter; the backend unwraps the 16-bit GigE Vision block ids), first to last
                 frame seen
  stored         frames of that span the service returned
  not stored     delivered - stored
  dropped        the camera's frames_dropped counted by the service during the run (incomplete
                 buffers and block ids that never arrived); with --loss 0 on loopback, 0
  arrival->stored     t_stored - t_capture: t_capture is the frame's arrival on the host
                      (timestamp=host: when its first packet arrived); includes Aravis completing
                      the frame, the copy out of the buffer, the hook, the copy into the ring
  available->stored   t_stored - t_available: t_available is when the camera worker had the
                      frame (grab returned): the worker's own share (hook + ring copy)
  fps            the rate the service measured (its status at the end of the run)
  period         t_capture of a frame minus that of the frame before it (consecutive ids):
                 the camera's period as the service stamps it; with --timestamp device, the
                 device's clock mapped onto the host's (arrival->stored is then capture->stored)

(tests/backends/test_aravis.py asserts what is stored is complete, in order and accounted
for; the rates, losses, periods and delays on this machine are this bench's.)

Goal: every complete frame stored (not stored == dropped, both 0 without --loss).

Writes gige.json (settings, status before/after, every frame's times) and gige.png (CDFs of
arrival->stored) into --out, and the services' logs. Exit status 0 if every frame the cameras
delivered was stored or counted as dropped and no request failed; 1 otherwise; 2 on bad flags.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import signal
import subprocess
import sys
import time

if not __package__:  # run as a script (python bench/cameras/gige.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common
from tests.hosts import loopback_address

BENCH_DIR = os.path.dirname(os.path.abspath(__file__))
EMULATOR = "arv-fake-gv-camera-0.8"
ADDRESSES = ("127.0.0.1", "127.0.0.2")
CAMERAS = ("cam0", "cam1")
HOOK = "slow_hooks:sleep_10ms"
HOOK_COST_MS = 10.0


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    p.add_argument("--seconds", type=common.positive_float, default=60.0, help="length of each run")
    p.add_argument("--fps", type=common.positive_float, default=20.0)
    common.add_frame_size_args(p, 640, 480)
    p.add_argument("--pixel-format", default="Mono8", help="Mono8, Mono16, RGB8, BayerRG8, ...")
    p.add_argument(
        "--timestamp",
        choices=("host", "device"),
        default="host",
        help="t_capture: the frame's arrival on the host, or the emulator's own clock mapped onto the host's",
    )
    p.add_argument(
        "--loss",
        type=common.int_between(0, 1000),
        default=0,
        metavar="N",
        help="the emulators drop N GVSP packets per thousand (-r N)",
    )
    p.add_argument("--slots", type=common.positive_int, default=64, help="frames per camera ring")
    p.add_argument(
        "--poll", type=common.positive_float, default=0.25, help="seconds between the bench's range requests"
    )
    p.add_argument("--no-hook-run", action="store_true", help="skip the run with the processing hook")
    g = p.add_argument_group("output")
    g.add_argument(
        "--out", default=common.DEFAULT_OUT, metavar="DIR", help="folder for gige.json, gige.png and the service logs"
    )
    g.add_argument("--timeout", type=float, default=3.0, metavar="S", help="client timeout per request")
    return p


# ---- the emulators ---------------------------------------------------------------------------


@contextlib.contextmanager
def emulators(loss: int, log_dir: str):
    """Two emulators, serials GV01 and GV02; killed on exit."""
    from fxis_shm.service.tether import die_with_parent
    from fxis_shm.workers.backends.aravis_library import load_aravis

    load_aravis()  # fails here, naming the extra, if PyGObject or Aravis is missing
    if shutil.which(EMULATOR) is None:
        raise RuntimeError(f"{EMULATOR} is not installed (Debian package aravis-tools)")
    procs = []
    try:
        with loopback_address(ADDRESSES[1]):
            for j, address in enumerate(ADDRESSES):
                args = [EMULATOR, "-i", address, "-s", f"GV{j + 1:02d}"] + (["-r", str(loss)] if loss else [])
                log = open(os.path.join(log_dir, f"gige.emulator{j}.log"), "wb")
                procs.append(
                    subprocess.Popen(args, stdout=log, stderr=log, stdin=subprocess.DEVNULL, preexec_fn=die_with_parent)
                )
                log.close()
            time.sleep(0.3)
            for proc in procs:
                if proc.poll() is not None:
                    raise RuntimeError(f"{' '.join(proc.args)} exited with code {proc.returncode}")
            yield [f"Aravis-Fake-GV{j + 1:02d}" for j in range(len(ADDRESSES))]
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGKILL)
                proc.wait(5)


# ---- one run -----------------------------------------------------------------------------------


def camera_flags(args, device_ids, process: str | None) -> list[str]:
    flags = []
    for name, device in zip(CAMERAS, device_ids):
        opts = [
            f"device={device}",
            f"fps={args.fps:g}",
            f"width={args.width}",
            f"height={args.height}",
            f"pixel_format={args.pixel_format}",
            f"timestamp={args.timestamp}",
        ]
        if process:
            opts.append(f"process={process}")
        flags += ["--camera", f"{name}=aravis:" + ",".join(opts)]
    return flags + ["--slots", str(args.slots)]


def collect(client, readers: dict, cursors: dict, frames: dict, end: int, errors: list) -> None:
    """New frames of every camera captured up to ``end``: a range request each, joined
    with t_available from the ring's slot table."""
    for cam in CAMERAS:
        available = {}
        snap = readers[cam].snapshot()
        for i in range(len(snap.timeline)):
            m = snap.frame_meta(i)
            available[(m.generation, m.frame_id, m.t_capture)] = m.t_available
        try:
            reply = client.sequence("range", camera=cam, start=cursors[cam], end=end)
        except common.REQUEST_ERRORS as exc:
            errors.append({"camera": cam, "start": cursors[cam], "end": end, "error": common.describe_error(exc)})
            cursors[cam] = end + 1  # go on after the gap (it shows as frames not stored)
            continue
        for f in reply:
            frames[cam][(f.generation, f.frame_id)] = {
                "frame_id": f.frame_id,
                "generation": f.generation,
                "t_capture": f.t_capture,
                "t_stored": f.t_stored,
                "t_available": available.get((f.generation, f.frame_id, f.t_capture)),
            }
        if reply:
            cursors[cam] = reply[-1].t_capture + 1


def measure(args, device_ids, label: str, process: str | None, out: str) -> dict:
    from fxis_shm.shm.ring import RingReader

    run_args = camera_flags(args, device_ids, process)
    log_path = os.path.join(out, f"gige.{label.replace(' ', '_')}.service.log")
    frames = {cam: {} for cam in CAMERAS}
    errors: list = []
    with common.service(None, run_args, log_path, args.timeout) as (client, info):
        status_ready = common.wait_until_streaming(client, min_frames=3, timeout=30)
        name = status_ready["service"]
        readers = {cam: RingReader(name, cam, with_semaphore=False) for cam in CAMERAS}
        try:
            lag = 150_000_000  # ask only for frames surely stored by now
            status_before = client.status()
            start = time.monotonic_ns()
            cursors = {cam: start for cam in CAMERAS}
            deadline = time.monotonic() + args.seconds
            polls = int(args.seconds / args.poll)
            with common.progress(polls, f"gige {label}") as bar:
                while time.monotonic() < deadline:
                    time.sleep(args.poll)
                    collect(client, readers, cursors, frames, time.monotonic_ns() - lag, errors)
                    bar.update(1)
            end = time.monotonic_ns() - lag
            time.sleep(lag / 1e9 + 0.05)
            collect(client, readers, cursors, frames, end, errors)
            status_after = client.status()
        finally:
            for reader in readers.values():
                reader.close()
    return {
        "label": label,
        "process": process,
        "service": info,
        "window_ns": [start, end],
        "status_before": status_before,
        "status_after": status_after,
        "errors": errors,
        "frames": {
            cam: sorted(frames[cam].values(), key=lambda r: (r["generation"], r["frame_id"])) for cam in CAMERAS
        },
    }


def summarise(run: dict) -> dict:
    rows = {}
    for cam in CAMERAS:
        recs = run["frames"][cam]
        delivered = 0
        for gen in sorted({r["generation"] for r in recs}):
            ids = [r["frame_id"] for r in recs if r["generation"] == gen]
            delivered += max(ids) - min(ids) + 1
        before, after = run["status_before"]["cameras"][cam], run["status_after"]["cameras"][cam]
        arrival = [common.ms(r["t_stored"] - r["t_capture"]) for r in recs]
        periods = [
            common.ms(b["t_capture"] - a["t_capture"])
            for a, b in zip(recs, recs[1:])
            if b["generation"] == a["generation"] and b["frame_id"] == a["frame_id"] + 1
        ]
        available = [common.ms(r["t_stored"] - r["t_available"]) for r in recs if r["t_available"] is not None]
        rows[cam] = {
            "delivered": delivered,
            "stored": len(recs),
            "not_stored": delivered - len(recs),
            "dropped": after["frames_dropped"] - before["frames_dropped"],
            "generations": sorted({r["generation"] for r in recs}),
            "arrival_to_stored_ms": common.summary(arrival),
            "available_to_stored_ms": common.summary(available),
            "period_ms": common.summary(periods),
            "fps": after.get("fps"),
        }
    return rows


def plot(runs: list[dict], path: str, title: str) -> None:
    plt = common.pyplot()
    import numpy as np

    fig, ax = plt.subplots(figsize=(9, 5))
    for run in runs:
        for cam in CAMERAS:
            x = np.sort([common.ms(r["t_stored"] - r["t_capture"]) for r in run["frames"][cam]])
            if x.size:
                ax.step(
                    x,
                    np.arange(1, x.size + 1) / x.size,
                    where="post",
                    label=f"{run['label']}, {cam} (median {np.median(x):.2f} ms)",
                )
    ax.set_xlabel("arrival -> stored, ms (t_stored - t_capture, timestamp=host)")
    ax.set_ylabel("fraction of frames (CDF)")
    ax.set_title(title.replace(" (", "\n("), fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parsed = common.parse_args_and_out(parser(), argv)
    if isinstance(parsed, int):
        return parsed
    args, out = parsed
    os.environ["PYTHONPATH"] = BENCH_DIR + os.pathsep + os.environ.get("PYTHONPATH", "")
    host = common.host_info()
    started = time.time()
    plan = [("no hook", None)] + ([] if args.no_hook_run else [("hook 10 ms", HOOK)])
    runs = []
    try:
        with emulators(args.loss, out) as device_ids:
            for label, process in plan:
                runs.append(measure(args, device_ids, label, process, out))
    except (RuntimeError, ImportError) as exc:
        print(f"gige: {exc}", file=sys.stderr)
        return common.EXIT_FAILED

    summaries = [summarise(run) for run in runs]
    title = (
        f"gige: 2 emulated GigE Vision cameras ({EMULATOR}, loopback{f', -r {args.loss}' if args.loss else ''}) "
        f"{args.width}x{args.height} {args.pixel_format} at {args.fps:g} fps, timestamp={args.timestamp}, "
        f"{args.seconds:g} s per run"
    )
    rows = []
    for run, summ in zip(runs, summaries):
        for cam in CAMERAS:
            s = summ[cam]
            a, v, t = s["arrival_to_stored_ms"], s["available_to_stored_ms"], s["period_ms"]
            rows.append(
                [
                    f"{run['label']}  {cam}",
                    s["delivered"],
                    s["stored"],
                    s["not_stored"],
                    s["dropped"],
                    a["median"],
                    a["p99"],
                    a["max"],
                    v["median"],
                    v["p99"],
                    s["fps"],
                    t["median"],
                    t["min"],
                    t["max"],
                ]
            )
    print(common.code_line(host["code"]))
    print(title)
    print(
        common.table(
            [
                "run  camera",
                "delivered",
                "stored",
                "not stored",
                "dropped",
                "arr->st med",
                "p99",
                "max",
                "avail->st med",
                "p99",
                "fps",
                "period med",
                "min",
                "max",
            ],
            rows,
            digits=2,
            separators=(5, 8, 10),
        )
    )
    print(
        "delivered: span of the frame ids the camera sent; dropped: frames_dropped counted by the service "
        "during the run; arr->st: t_stored - t_capture (arrival on the host), avail->st: t_stored - "
        f"t_available (the worker's share), ms; the hook costs {HOOK_COST_MS:g} ms; fps: measured by "
        "the service; period: t_capture of consecutive frames, ms"
    )
    errors = [e for run in runs for e in run["errors"]]
    unaccounted = sum(max(0, s["not_stored"] - s["dropped"]) for summ in summaries for s in summ.values())
    print(f"failed requests: {len(errors)}; frames neither stored nor counted as dropped: {unaccounted}")
    for e in errors[:10]:
        print(f"  failed: {e['camera']}: {e['error']}")

    json_path, png_path = os.path.join(out, "gige.json"), os.path.join(out, "gige.png")
    common.write_json(
        json_path,
        {
            **common.run_record("gige", started, argv, args),
            "host": host,
            "hook": {"process": HOOK, "cost_ms": HOOK_COST_MS},
            "clock": "CLOCK_MONOTONIC ns; t_capture: "
            + (
                "the host arrival time (timestamp=host)"
                if args.timestamp == "host"
                else "the device's clock mapped onto the host's (timestamp=device)"
            ),
            "summary": [{"label": run["label"], "cameras": summ} for run, summ in zip(runs, summaries)],
            "unaccounted": unaccounted,
            "runs": runs,
        },
    )
    plot(runs, png_path, title)
    print(f"wrote {json_path} and {png_path}")
    return common.EXIT_FAILED if errors or unaccounted else common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
