"""How late does a scheduled GigE Vision action fire? The responder's fired time minus T.

Sends --count scheduled ACTION_CMDs (fxis_shm/client/actions.py), one after the other, each
for T = the device clock's now + --lead-ms, to the project's action-command responder
(tests/gvcp_responder.py: an emulated device clock, CLOCK_REALTIME + --offset-s, that sleeps to
2 ms before T, then spins) over UDP on loopback, and prints the distribution of
fired - T, where "fired" is the device clock read just before the action's callback runs.

With --camera ADDRESS the callback is the Aravis fake camera's TriggerSoftware
(arv-fake-gv-camera-0.8 started on ADDRESS, which must be on lo: `ip addr add ADDRESS/8 dev lo`),
and the time that GVCP write takes is printed too; without it the callback does nothing, and
the figure is the responder's own timer. Neither is a camera's exposure: a real camera fires
in hardware, from a PTP-disciplined clock (70-128 ns spreads are reported for Basler's).

    .venv/bin/python bench/cameras/action_commands.py --count 200 [--camera 127.0.0.36]
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))  # tests.*

from fxis_shm.client.actions import ActionSender, check  # noqa: E402
from tests.gvcp_responder import ActionResponder  # noqa: E402

KEYS = (0x0FEEDBAC, 1, 0xFFFFFFFF)
PERCENTILES = (0, 50, 90, 99, 100)


def distribution(label: str, values_ns: list[int]) -> str:
    a = np.asarray(values_ns, dtype=float) / 1000.0
    cells = "  ".join(f"p{p}={np.percentile(a, p):8.1f}" for p in PERCENTILES)
    return f"{label:<28} n={a.size}  mean={a.mean():8.1f}  std={a.std():7.1f}  {cells}   (µs)"


def histogram(values_ns: list[int], edges_us=(0, 10, 20, 50, 100, 200, 500, 1000, 2000)) -> list[str]:
    a = np.asarray(values_ns, dtype=float) / 1000.0
    counts, _ = np.histogram(a, bins=[*edges_us, max(a.max(), edges_us[-1]) + 1])
    lines = []
    for low, high, n in zip(edges_us, [*edges_us[1:], "inf"], counts):
        lines.append(f"  [{low:>5}, {high:>5}) µs {n:5d} {'#' * int(round(60 * n / len(a)))}")
    return lines


def run(args) -> int:
    camera = emulator = None
    if args.camera:
        from tests.aravis_trigger import TriggeredCamera
        from tests.backends.conftest import Emulator

        emulator = Emulator(args.camera, "BENCH1").start()
        camera = TriggeredCamera(emulator.device_id)
    load_before = os.getloadavg()
    try:
        fire = camera.trigger if camera else (lambda: None)
        offset = int(args.offset_s * 1e9)
        with ActionResponder("127.0.0.1", port=0, fire=fire, clock_offset_ns=offset) as device:
            host, port = device.address
            with ActionSender(*KEYS, port=port) as sender:
                for i in range(args.count):
                    at = device.now() + int(args.lead_ms * 1e6)
                    check(sender.fire([host], action_time=at))
                    device.wait_fired(i + 1, timeout=5 + args.lead_ms / 1000)
                    if camera and camera.frame(timeout=5) is None:
                        print(f"action {i}: the camera's frame never arrived", file=sys.stderr)
                        return 1
            fired = device.fired
            if device.errors:
                print(f"the callback failed: {device.errors[0]}", file=sys.stderr)
                return 1
    finally:
        if camera:
            camera.close()
        if emulator:
            emulator.kill()
    late = [f.called_ns - f.action_time for f in fired]
    print(
        f"{args.count} scheduled actions, T = now + {args.lead_ms:g} ms on a device clock {args.offset_s:g} s "
        f"ahead of the host's; {os.cpu_count()} CPUs, load average {load_before[0]:.2f} before, "
        f"{os.getloadavg()[0]:.2f} after"
    )
    print(distribution("fired - T", late))
    for line in histogram(late):
        print(line)
    if camera:
        print(distribution("TriggerSoftware call", [f.returned_ns - f.called_ns for f in fired]))
        print(distribution("fired - T, call returned", [f.returned_ns - f.action_time for f in fired]))
    print(f"never early: {min(late) >= 0}")
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--count", type=int, default=200, help="actions to send (default 200)")
    p.add_argument("--lead-ms", type=float, default=100.0, help="T = now + this (default 100 ms)")
    p.add_argument("--offset-s", type=float, default=1000.0, help="device clock minus host clock (default 1000 s)")
    p.add_argument("--camera", metavar="ADDRESS", help="fire arv-fake-gv-camera-0.8 started on ADDRESS (on lo)")
    args = p.parse_args(argv)
    if args.count < 1 or args.lead_ms <= 0:
        p.error("--count must be at least 1 and --lead-ms positive")
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
