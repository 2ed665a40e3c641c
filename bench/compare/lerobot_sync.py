"""Compare: the skew of what a LeRobot robot observes, per control tick, when it reads its
cameras as LeRobot's own cameras do (each camera's newest frame, read in turn) and when it reads
them through the fxis plugin (lerobot_camera_fxis: one joint tuple per tick), on the same cameras
in the same ticks; and what the plugin's reads cost per tick.

Run in the LeRobot venv (`make .venv-lerobot/.installed`):

    .venv-lerobot/bin/python bench/compare/lerobot_sync.py --ticks 600

Two fxis services on this host (one clock): "top" and "side" (phase 9 ms) on one, "wrist" on
the other (its frame grid starts with its service, so its phase is whatever it is), synthetic
mono8 cameras at --fps. Each tick (a control loop at --fps) first reads the cameras
independently, as LeRobot's OpenCVCamera.read_latest does (here `client.latest([cam])`, each
camera's newest stored frame, in turn), then reads them through three FxisCamera made by
LeRobot's make_cameras_from_configs (read_latest each). Printed: the per-tick skew (max minus
min capture time of the tick's frames) of both, p50/p99/max in ms, the age of each tick's oldest
frame when its reads end (the plugin reads the best tuple already stored: about a period older),
and the plugin's read cost per tick (the three read_latest calls: one tuple request and three image copies with
their colour conversion) beside the independent reads' cost.
"""

import argparse
import sys
import time

import numpy as np

CAMERAS = {"top": 0, "side": 0, "wrist": 1}  # camera -> service


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ticks", type=int, default=600, help="control ticks measured (default 600)")
    parser.add_argument("--fps", type=int, default=30, help="the cameras' and the control loop's rate (default 30)")
    parser.add_argument("--size", default="640x480", help="the cameras' WIDTHxHEIGHT (default 640x480)")
    parser.add_argument("--jitter-ms", type=float, default=1.0, help="the cameras' capture jitter (default 1 ms)")
    args = parser.parse_args()
    try:
        import lerobot  # noqa: F401
    except ImportError:
        sys.exit("lerobot_sync.py needs lerobot: run it with .venv-lerobot/bin/python (make .venv-lerobot/.installed)")
    from fxis_shm.service.launch import ServiceProcess

    width, height = (int(v) for v in args.size.split("x"))
    small = f"fps={args.fps},width={width},height={height},jitter_ms={args.jitter_ms}"
    services = [
        ServiceProcess(["--camera", f"top=synthetic:{small}", "--camera", f"side=synthetic:{small},phase_ms=9"]),
        ServiceProcess(["--camera", f"wrist=synthetic:{small}"]),
    ]
    try:
        for svc in services:
            svc.start()
        measure([svc.endpoint for svc in services], args)
    finally:
        for svc in services:
            svc.stop()


def measure(endpoints: list[str], args: argparse.Namespace) -> None:
    import draccus
    from lerobot.cameras.configs import CameraConfig
    from lerobot.cameras.utils import make_cameras_from_configs
    from lerobot.utils.import_utils import register_third_party_plugins

    from fxis_shm import Client

    register_third_party_plugins()
    common = {"type": "fxis", "endpoint": endpoints, "fps": args.fps, "warmup_s": 10.0}
    configs = {cam: draccus.decode(CameraConfig, {**common, "camera": cam}) for cam in CAMERAS}
    cameras = make_cameras_from_configs(configs)
    owners = [Client(endpoint) for endpoint in endpoints]
    for cam in cameras.values():
        cam.connect()
    independent, plugin, independent_cost, plugin_cost, independent_age, plugin_age = [], [], [], [], [], []
    period = 1 / args.fps
    next_tick = time.monotonic()
    try:
        for _ in range(args.ticks):
            next_tick += period
            time.sleep(max(0.0, next_tick - time.monotonic()))
            start = time.perf_counter_ns()
            times = [owners[service].latest([cam])[cam].t_capture for cam, service in CAMERAS.items()]
            independent_cost.append(time.perf_counter_ns() - start)
            independent.append(max(times) - min(times))
            independent_age.append(time.monotonic_ns() - min(times))
            start = time.perf_counter_ns()
            for cam in cameras.values():
                cam.read_latest()
            plugin_cost.append(time.perf_counter_ns() - start)
            record = next(iter(cameras.values())).last_record
            plugin.append(record.skew_ns)
            plugin_age.append(time.monotonic_ns() - min(record.t_capture.values()))
    finally:
        for cam in cameras.values():
            cam.disconnect()
        for client in owners:
            client.close()
    print(
        f"3 synthetic cameras {args.size} mono8 at {args.fps} fps (jitter {args.jitter_ms} ms) on 2 services, "
        f"{args.ticks} ticks at {args.fps} Hz"
    )
    print(f"{'per tick':44s} {'p50':>8s} {'p99':>8s} {'max':>8s}  (ms)")
    row("skew, LeRobot-style independent read_latest", independent)
    row("skew, fxis plugin (one joint tuple a tick)", plugin)
    row("age of the oldest frame, independent", independent_age)
    row("age of the oldest frame, fxis plugin", plugin_age)
    row("read cost, independent newest frames", independent_cost)
    row("read cost, fxis plugin (3 x read_latest)", plugin_cost)


def row(name: str, values_ns: list[int]) -> None:
    p50, p99, top = (np.percentile(values_ns, q) / 1e6 for q in (50, 99, 100))
    print(f"{name:44s} {p50:8.2f} {p99:8.2f} {top:8.2f}")


if __name__ == "__main__":
    main()
