"""How long a live change of a camera's settings takes to show in its frames (issue 36).

For each camera kind, a real service is started with one camera; a subscriber of the
camera's ``frames/<camera>|`` stream sees every frame. Then, ``--changes`` times, a live
change is sent (``client.configure``) and timed from the moment of the request to:

- ``reply``: the answer (the worker applied it between two frames);
- ``capture``: t_capture of the first frame whose pixels show the new setting;
- ``stored``: t_stored of that frame (when a reader could have it);
- ``old``: how many frames captured after the request still showed the old setting.

The change alternates between two values a frame's pixels tell apart:

- synthetic: exposure_us 10000 <-> 5000 (brightness x 1 or x 0.5);
- aravis (``arv-fake-gv-camera-0.8``, started here on 127.0.0.1): exposure_us 10000 <->
  3162 (its picture scales with 1 + log10(exposure / 10 ms): x 1 or x 0.5);
- genicam (viky.cti, which has no exposure or gain): BouncingBallSize 20 <-> 40, a node-map
  feature set by name (the ball's area changes the white fraction).

Every time is CLOCK_MONOTONIC of this host, which the service shares. Standalone: only
fxis_shm, numpy and, for their kinds, the emulators. Run:

    .venv/bin/python bench/latency/settings_change.py --changes 40
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))

from fxis_shm.service.launch import ServiceProcess  # noqa: E402

FAKE_CAMERA = "arv-fake-gv-camera-0.8"


def _viky() -> str:
    import genicam

    return os.path.join(os.path.dirname(genicam.__file__), "viky.cti")


# kind: (--camera value, the key changed, its two values, a number of a frame's pixels that tells them apart)
KINDS = {
    "synthetic": (
        "synthetic:fps=20,width=640,height=480",
        "exposure_us",
        (10_000.0, 5000.0),
        lambda image: float(image[8:-8].mean()),
    ),
    "aravis": (
        "aravis:device=Aravis-Fake-GVBENCH,fps=20,width=640,height=480,pixel_format=Mono8",
        "exposure_us",
        (10_000.0, 3162.3),
        lambda image: float(image.mean()),
    ),
    "genicam": (
        "genicam:cti={viky},device=0",
        "BouncingBallSize",
        (20, 40),
        lambda image: float((image < 250).mean()),
    ),
}


def _start_fake_camera() -> subprocess.Popen:
    if shutil.which(FAKE_CAMERA) is None:
        raise SystemExit(f"{FAKE_CAMERA} is not installed (Debian package aravis-tools)")
    proc = subprocess.Popen(
        [FAKE_CAMERA, "-i", "127.0.0.1", "-s", "GVBENCH"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    time.sleep(1.0)
    if proc.poll() is not None:
        raise SystemExit(f"{FAKE_CAMERA} exited (another GigE Vision device on 127.0.0.1:3956?)")
    return proc


def _measure(svc: ServiceProcess, key: str, values: tuple, signal_of, changes: int) -> dict:
    rows = []
    with svc.client(timeout=15) as client, client.subscribe(timeout=5) as sub:
        client.configure("cam", **{key: values[0]})
        sub.frames("cam")
        for _ in range(20):  # the stream flows, and both levels' signals are learnt
            sub.receive()
        levels = []
        for value in (values[1], values[0]):
            client.configure("cam", **{key: value})
            time.sleep(0.4)
            while True:  # the newest frame queued
                try:
                    message = sub.receive(timeout=0.01)
                except Exception:
                    break
            levels.append(signal_of(message.frames[0].image))
        threshold = sum(levels) / 2
        new_is_high = levels[0] > levels[1]  # values[1]'s level is the higher one
        for i in range(changes):
            value = values[(i + 1) % 2]
            high = new_is_high if value == values[1] else not new_is_high
            t_request = time.monotonic_ns()
            client.configure("cam", **{key: value})
            t_reply = time.monotonic_ns()
            old = 0
            while True:
                frame = sub.receive(timeout=5).frames[0]
                if frame.t_capture < t_request:
                    continue
                if (signal_of(frame.image) > threshold) == high:
                    break
                old += 1
            rows.append((t_reply - t_request, frame.t_capture - t_request, frame.t_stored - t_request, old))
            time.sleep(0.1 + 0.1 * (i % 3) / 3)  # requests at varied phases of the frame period
    a = np.array(rows, dtype=float)
    ms = lambda column, q: round(float(np.percentile(a[:, column], q)) / 1e6, 2)  # noqa: E731
    return {
        "changes": changes,
        "levels": [round(x, 3) for x in levels],
        "reply_ms": {"p50": ms(0, 50), "p95": ms(0, 95), "max": ms(0, 100)},
        "capture_ms": {"p50": ms(1, 50), "p95": ms(1, 95), "max": ms(1, 100)},
        "stored_ms": {"p50": ms(2, 50), "p95": ms(2, 95), "max": ms(2, 100)},
        "old_frames": {"median": float(np.median(a[:, 3])), "max": int(a[:, 3].max())},
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--changes", type=int, default=40, help="live changes per camera kind")
    p.add_argument("--kinds", default=",".join(KINDS), help="comma-separated: synthetic, aravis, genicam")
    p.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    args = p.parse_args()
    results = {}
    for kind in args.kinds.split(","):
        camera, key, values, signal_of = KINDS[kind]
        fake = _start_fake_camera() if kind == "aravis" else None
        camera = "cam=" + camera.format(viky=_viky() if kind == "genicam" else "")
        svc = ServiceProcess(["--camera", camera], stderr=subprocess.DEVNULL)
        try:
            svc.start()
            results[kind] = {"key": key, "values": list(values), **_measure(svc, key, values, signal_of, args.changes)}
        finally:
            svc.stop()
            if fake is not None:
                fake.send_signal(signal.SIGTERM)
                fake.wait(5)
    load = os.getloadavg()
    print(f"live change -> first frame showing it; {args.changes} changes per kind; load {load[0]:.2f} (1 min)")
    print(
        f"{'kind':<10} {'key':<17} {'reply ms p50/p95':>17} {'capture ms p50/p95/max':>24} "
        f"{'stored ms p50/p95':>18} {'old frames med/max':>19}"
    )
    for kind, r in results.items():
        print(
            f"{kind:<10} {r['key']:<17} {r['reply_ms']['p50']:>8}/{r['reply_ms']['p95']:<8} "
            f"{r['capture_ms']['p50']:>9}/{r['capture_ms']['p95']}/{r['capture_ms']['max']:<7} "
            f"{r['stored_ms']['p50']:>9}/{r['stored_ms']['p95']:<8} "
            f"{r['old_frames']['median']:>10}/{r['old_frames']['max']}"
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"load_1min": load[0], "results": results}, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
