"""Capture at T with the Aravis fake camera: the residual t_capture - T once the worker learned
the camera's trigger latency.

Starts GigE Vision camera emulators (arv-fake-gv-camera-0.8, bench/cameras/gige.py's: the second
address on lo needs root) and one `fxis run` service with the first as a software-triggered
aravis camera (64x48 Mono8). Sends --requests ``client.image(at=now + --lead-ms, capture=True)``
one after the other, the first 3 not counted (the worker learns the latency from them), and
prints the residuals' distribution, signed and absolute (ms), the worker's learned latency and
timer lateness, whether the camera stayed up, and the machine's load.

    .venv/bin/python bench/cameras/aravis_capture_at.py --requests 200

The fake camera answers TriggerSoftware on the next tick of its own frame loop (25 Hz), so its
latency spreads over one tick (40 ms): the residuals say that, not the timer's jitter.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

if not __package__:  # run as a script: the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))

from bench.cameras.gige import emulators  # noqa: E402
from bench.shared import common  # noqa: E402

LEARNING = 3  # requests that teach the worker the latency, not counted
PERCENTILES = (0, 1, 50, 99, 100)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--requests", type=common.positive_int, default=200, help="captures at T (default 200)")
    p.add_argument("--lead-ms", type=common.positive_float, default=100.0, help="T = now + this (default 100)")
    args = p.parse_args(argv)
    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as out, emulators(0, out) as (device, _):
        camera = f"a=aravis:device={device},trigger=software,width=64,height=48,pixel_format=Mono8"
        with common.service(None, ["--camera", camera], os.path.join(out, "service.log"), 15.0) as (client, _):
            generation = client.status()["cameras"]["a"]["generation"]
            residuals = []
            for _ in range(args.requests + LEARNING):
                at = time.monotonic_ns() + round(args.lead_ms * 1e6)
                residuals.append(client.image("a", at=at, capture=True, timeout=10).residual_ns)
            status = client.status()["cameras"]["a"]
    signed = np.asarray(residuals[LEARNING:], dtype=float) / 1e6
    for label, values in (("t_capture - T", signed), ("|t_capture - T|", np.abs(signed))):
        cells = "  ".join(f"p{q}={np.percentile(values, q):8.3f}" for q in PERCENTILES)
        print(f"{label:<16} n={values.size:<5} {cells}   (ms)")
    sync = status["sync"]
    print(
        f"learned latency {sync['trigger_latency_ms']:.3f} ms, timer late p50 {sync['timer_late_p50_ms']:.3f} "
        f"p99 {sync['timer_late_p99_ms']:.3f} ms, {sync['frames_scheduled']} scheduled, "
        f"{sync['triggers_missed']} missed; camera alive {status['alive']}, "
        f"generation {generation} -> {status['generation']}"
    )
    print(f"{os.cpu_count()} CPUs, load average {load[0]:.2f} before, {os.getloadavg()[0]:.2f} after")
    return 0


if __name__ == "__main__":
    sys.exit(main())
