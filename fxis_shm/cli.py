"""The ``fxis`` command: run, status, grab, record, clean."""

from __future__ import annotations

import argparse
import json
import logging
import os
import subprocess
import sys
import textwrap

from fxis_shm.client.client import Client
from fxis_shm.errors import ConfigError, FxisError
from fxis_shm.service.camerakinds import COMMON_OPTIONS, KINDS
from fxis_shm.service.config import DEFAULT_FOXGLOVE_RATE_HZ, MAX_FOXGLOVE_RATE_HZ, build_config, load_toml
from fxis_shm.shm import naming
from fxis_shm.wire import defaults

EXIT_USAGE = 2


def _run(args) -> int:
    from fxis_shm.service.supervisor import StartError, Supervisor

    try:
        file_values = load_toml(args.config) if args.config else {}
        config = build_config(
            file_values,
            {
                "name": args.name,
                "endpoint": args.endpoint,
                "pub": args.pub,
                "events": args.events,
                "slots": args.slots,
                "cameras": args.camera,
                "restart_limit": args.restart_limit,
                "log_level": args.log_level,
                "curve_secret": args.curve_secret,
                "curve_clients": args.curve_clients,
                "insecure_bind": args.insecure_bind or None,
                "clock": args.clock,
                "http": args.http,
                "foxglove": args.foxglove,
                "foxglove_rate": args.foxglove_rate,
                "ros2": args.ros2 or None,
                "ros2_domain": args.ros2_domain,
                "ros2_namespace": args.ros2_namespace,
                "ros2_tuples": args.ros2_tuples,
            },
        )
    except ConfigError as exc:
        print(f"fxis run: {exc}", file=sys.stderr)
        return EXIT_USAGE
    logging.basicConfig(level=config.log_level, format="%(asctime)s supervisor %(levelname)s %(message)s")
    try:
        return Supervisor(config).run()
    except StartError as exc:
        print(f"fxis run: {exc}", file=sys.stderr)
        return 1


def _status(args) -> int:
    with Client(args.endpoint, timeout=args.timeout) as client:
        status = client.status()
        # this host's view of the service's clock (what a client here maps times with)
        status["clock_mapping"] = client.clock_estimate().as_dict()
    if args.json:
        print(json.dumps(status, indent=2))
        return 0
    print(
        f"service {status['service']!r}  uptime {status['uptime_s']:.1f} s  "
        f"requests {status['requests_served']}  waiting {status['pending']}"
    )
    mapping = status["clock_mapping"]
    print(
        f"clock {status.get('clock', 'monotonic')}: {mapping['method']}, offset from this host's monotonic "
        f"{mapping['offset_ns'] / 1e6:+.3f} ms, drift {mapping['drift_ppm']:+.2f} ppm, "
        f"uncertainty {mapping['uncertainty_ns'] / 1e3:.0f} us"
    )
    columns = ["camera", "kind", "alive", "shape", "fps", "stored", "dropped", "age_ms", "slots", "gen", "torn"]
    rows = []
    for name, cam in status["cameras"].items():
        shape = "x".join(map(str, cam.get("shape", []))) or "-"
        rows.append(
            [
                name,
                cam["kind"],
                "yes" if cam["alive"] else "NO",
                shape,
                cam.get("fps"),
                cam.get("frames_stored"),
                cam.get("frames_dropped"),
                cam.get("last_frame_age_ms"),
                cam.get("ring_slots"),
                cam.get("generation"),
                cam.get("torn_reads"),
            ]
        )
    cells = [columns] + [["-" if v is None else str(v) for v in r] for r in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(columns))]
    for row in cells:
        print("  ".join(v.ljust(w) for v, w in zip(row, widths)).rstrip())
    for name, cam in status["cameras"].items():
        if not cam["alive"] and cam.get("reason"):
            print(f"  {name}: {cam['reason']}")
    if status.get("ros2"):
        print(_ros2_line(status["ros2"]))
    return 0


def _ros2_line(ros2: dict) -> str:
    """What the ROS 2 bridge reported: frames published and skipped per camera, frames_at."""
    cameras = ", ".join(f"{n} {c['published']} ({c['skipped']} skipped)" for n, c in ros2["cameras"].items())
    asked = ros2["frames_at"]
    return (
        f"ros2 on domain {ros2['domain']} under {ros2['namespace'] or '/'}: published {cameras}; "
        f"frames_at answered {asked['published']}, refused {asked['refused']}"
    )


def _grab(args) -> int:
    from fxis_shm.formats.tuplefiles import tuple_files

    cameras = args.cameras.split(",") if args.cameras else None
    with Client(args.endpoint, timeout=args.timeout) as client:
        frames = client.tuple(cameras=cameras, at=args.at)
    files = tuple_files(frames)
    os.makedirs(args.out, exist_ok=True)
    for name, data in files.items():
        path = os.path.join(args.out, name)
        try:
            with open(path, "wb") as f:
                f.write(data)
        except OSError as exc:
            print(f"fxis grab: could not write {path}: {exc.strerror}", file=sys.stderr)
            return 1
    print(f"saved {len(frames)} image(s) and tuple.json to {args.out} (skew {frames.skew_ns / 1e6:.3f} ms)")
    return 0


def _record(args) -> int:
    from fxis_shm.record.recorder import Recorder, RecordSettings, summary_table
    from fxis_shm.wire import encoding

    def usage(message: str) -> int:
        print(f"fxis record: {message}", file=sys.stderr)
        return EXIT_USAGE

    for flag, value in (("--seconds", args.seconds), ("--frames", args.frames), ("--rate", args.rate)):
        if value is not None and not value > 0:
            return usage(f"{flag} must be > 0, got {value}")
    if args.quality is not None and args.encoding != encoding.JPEG:
        return usage("--quality applies to --encoding jpeg only")
    if args.quality is not None and not 1 <= args.quality <= 100:
        return usage(f"--quality must be from 1 to 100, got {args.quality}")
    cameras = [c.strip() for c in args.cameras.split(",") if c.strip()] if args.cameras else None
    if args.cameras is not None and not cameras:
        return usage("--cameras names no camera")
    settings = RecordSettings(
        out=args.out,
        endpoint=args.endpoint,
        cameras=cameras,
        seconds=args.seconds,
        frames=args.frames,
        rate_hz=args.rate,
        tuples=args.tuples,
        encoding=args.encoding,
        quality=args.quality or encoding.DEFAULT_JPEG_QUALITY,
    )
    with Client(args.endpoint, timeout=args.timeout) as client:
        try:
            recorder = Recorder(settings, client)
        except ConfigError as exc:
            return usage(str(exc))
        summary = recorder.run()
    print(summary_table(summary))
    return 0


def _keys(args) -> int:
    from fxis_shm.wire.security import create_keys

    public, secret = create_keys(args.out, args.name)
    print(f"wrote {public} (public: give it to the other side) and {secret} (secret: keep it)")
    return 0


def _cameras(args) -> int:
    from fxis_shm.service.camerakinds import DISCOVERY_MODULE

    try:
        child = subprocess.run(
            [sys.executable, "-m", DISCOVERY_MODULE],
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=args.timeout,
        )
    except subprocess.TimeoutExpired:
        print(
            f"fxis cameras: the backends did not finish looking within {args.timeout:g} s (--timeout)", file=sys.stderr
        )
        return 1
    if child.returncode != 0:
        print(
            f"fxis cameras: looking for cameras failed (exit code {child.returncode}):\n{child.stderr.strip()}",
            file=sys.stderr,
        )
        return 1
    listing = json.loads(child.stdout)
    found, unavailable = listing["cameras"], listing["unavailable"]
    if args.json:
        print(json.dumps(listing, indent=2))
        return 0
    if found:
        rows = [["kind", "id (device=...)", "model", "format"]] + [
            [c["kind"], str(c["id"]), str(c.get("model", "-")), str(c.get("format", "-"))] for c in found
        ]
        widths = [max(len(r[i]) for r in rows) for i in range(4)]
        for row in rows:
            print("  ".join(v.ljust(w) for v, w in zip(row, widths)).rstrip())
    else:
        print("no cameras found")
    for kind, why in unavailable.items():
        print(f"({kind}: not available: {why})")
    return 0


def _clean(args) -> int:
    from fxis_shm.service.supervisor import service_running

    if service_running(args.name):
        print(f"fxis clean: service {args.name!r} is running; stop it first", file=sys.stderr)
        return 1
    removed = naming.remove_leftovers(args.name)
    for path in removed:
        print(f"removed {path}")
    if not removed:
        print(f"nothing of service {args.name!r} left in {naming.SHM_DIR}")
    return 0


def _kinds_help() -> str:
    """The camera kinds --camera takes, and their keys (docs/cameras.md tells more)."""
    lines = [f"camera kinds (KIND) and their keys (any kind also takes {', '.join(COMMON_OPTIONS)}):"]
    for kind in KINDS.values():
        lines += [
            f"  {kind.name:<10} {kind.description}",
            *textwrap.wrap(", ".join(kind.options), 88, initial_indent=" " * 13, subsequent_indent=" " * 13),
        ]
    return "\n".join(lines)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="fxis", description="Multi-camera acquisition service: synchronized images on request."
    )
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = sub.add_parser(
        "run",
        help="start the service (default: two synthetic cameras)",
        description="Start camera workers and the coordinator; Ctrl-C stops them and removes their shared memory.",
        epilog=_kinds_help(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    run.add_argument("--name", help=f"service name (default {defaults.SERVICE}); names its shared memory")
    run.add_argument(
        "--camera",
        action="append",
        metavar="NAME=KIND[:key=value,...]",
        help="a camera, e.g. left=synthetic:fps=30,phase_ms=5 (repeatable)",
    )
    run.add_argument("--endpoint", help=f"request/reply endpoint (default {defaults.ENDPOINT})")
    run.add_argument("--pub", help=f"publish endpoint (default {defaults.PUB})")
    run.add_argument("--events", help=f"endpoint receiving request events (default {defaults.EVENTS})")
    run.add_argument("--slots", type=int, help=f"frames held per camera ring (default {defaults.SLOTS})")
    run.add_argument("--config", metavar="FILE.toml", help="settings file (flags override it)")
    run.add_argument(
        "--clock",
        choices=("monotonic", "realtime", "tai"),
        help="the clock of every time the service gives and takes (default monotonic); "
        "realtime or tai where PTP or chrony keeps the cell's hosts in step "
        "(docs/deployment.md)",
    )
    run.add_argument(
        "--restart-limit",
        type=int,
        help=f"restarts of a crashed process before giving up (default {defaults.RESTART_LIMIT})",
    )
    run.add_argument("--log-level", help=f"DEBUG, INFO, WARNING or ERROR (default {defaults.LOG_LEVEL})")
    run.add_argument("--curve-secret", metavar="FILE", help="the service's NAME.key_secret: CurveZMQ on every socket")
    run.add_argument(
        "--curve-clients", metavar="DIR", help="folder of the public keys (.key) of the clients allowed in"
    )
    run.add_argument(
        "--insecure-bind",
        action="store_true",
        help="allow endpoints reachable from other hosts without CurveZMQ (prints a warning)",
    )
    run.add_argument(
        "--http",
        metavar="HOST:PORT|off",
        help=f"serve the live dashboard (pictures, rates, skew; docs/dashboard.md) here "
        f"(default {defaults.HTTP}); off: none. Another host's address needs "
        "--insecure-bind: HTTP has no authentication",
    )
    run.add_argument(
        "--foxglove",
        metavar="HOST:PORT|off",
        help="serve the cameras to the Foxglove app over its WebSocket protocol here, e.g. "
        "127.0.0.1:8765 (default off; needs the foxglove extra). Another host's "
        "address needs --insecure-bind: it has no authentication (docs/dashboard.md)",
    )
    run.add_argument(
        "--foxglove-rate",
        metavar="HZ",
        help=f"pictures a second per camera to Foxglove, at most {MAX_FOXGLOVE_RATE_HZ:g} "
        f"(default {DEFAULT_FOXGLOVE_RATE_HZ:g}); the app can change it live (parameter rate_hz)",
    )
    run.add_argument(
        "--ros2",
        action="store_true",
        help="join the ROS 2 graph: every camera's image_raw, image_raw/compressed and camera_info, "
        "and frames at t* on request (docs/ros2.md; needs the ros2 extra, no ROS install)",
    )
    run.add_argument(
        "--ros2-domain", metavar="ID", help="DDS domain of the ROS 2 topics (default: $ROS_DOMAIN_ID, else 0)"
    )
    run.add_argument("--ros2-namespace", metavar="NS", help="namespace of the ROS 2 topics, e.g. /cell1 (default none)")
    run.add_argument(
        "--ros2-tuples",
        metavar="HZ",
        help="also publish joint tuples at this rate on NS/tuple/NAME/image_raw, one header.stamp per tuple",
    )
    run.set_defaults(func=_run)

    def client_args(sp):
        sp.add_argument("--endpoint", default=defaults.ENDPOINT, help=f"service endpoint (default {defaults.ENDPOINT})")
        sp.add_argument("--timeout", type=float, default=3.0, help="seconds to wait for the reply (default 3)")

    status = sub.add_parser("status", help="show the cameras and the service")
    client_args(status)
    status.add_argument("--json", action="store_true", help="print the raw status as JSON")
    status.set_defaults(func=_status)

    grab = sub.add_parser("grab", help="save one synchronized tuple as PNG files plus JSON metadata")
    client_args(grab)
    grab.add_argument("--out", required=True, metavar="DIR", help="folder to write into")
    grab.add_argument("--cameras", help="comma-separated cameras (default all)")
    grab.add_argument(
        "--at", type=int, help="t* in ns of this host's CLOCK_MONOTONIC, mapped to the service's clock (default now)"
    )
    grab.set_defaults(func=_grab)

    record = sub.add_parser(
        "record",
        help="record the cameras into a rosbag2 bag (MCAP) for Foxglove, ros2 bag, rosbags",
        description="Record every frame of the cameras (or one synchronized tuple per step with "
        "--tuples) into a rosbag2 folder with MCAP storage: /NAME/image_raw "
        "(sensor_msgs/msg/Image) or /NAME/image_raw/compressed (JPEG), stamps in the "
        "service's clock (CLOCK_MONOTONIC unless fxis run --clock says otherwise). "
        "Ctrl-C ends the recording with a valid bag. "
        "Replay it with a camera of kind bag (docs/recording.md).",
    )
    client_args(record)
    record.add_argument("--out", required=True, metavar="DIR", help="the bag folder to create (must not exist)")
    record.add_argument("--cameras", metavar="A,B", help="comma-separated cameras (default all)")
    until = record.add_mutually_exclusive_group()
    until.add_argument("--seconds", type=float, metavar="S", help="stop after S seconds (default: at Ctrl-C)")
    until.add_argument(
        "--frames", type=int, metavar="N", help="stop after N frames per camera (N tuples with --tuples)"
    )
    record.add_argument(
        "--rate",
        type=float,
        metavar="HZ",
        help="thin each camera to HZ on purpose (default every frame); with --tuples, "
        "the step rate (default the slowest camera's)",
    )
    record.add_argument(
        "--tuples",
        action="store_true",
        help="one synchronized tuple per step: its images share the step's stamp, "
        "and /fxis/tuples lists their frame ids",
    )
    record.add_argument(
        "--encoding",
        choices=("raw", "jpeg"),
        default="raw",
        help="raw: sensor_msgs/Image (default); jpeg: sensor_msgs/CompressedImage",
    )
    record.add_argument("--quality", type=int, metavar="Q", help="JPEG quality 1-100 (default 90)")
    record.set_defaults(func=_record)

    keys = sub.add_parser("keys", help="make a CurveZMQ key pair (for a service or a client)")
    keys.add_argument("--out", required=True, metavar="DIR", help="folder to write NAME.key and NAME.key_secret into")
    keys.add_argument("--name", default=defaults.SERVICE, help=f"file name of the pair (default {defaults.SERVICE})")
    keys.set_defaults(func=_keys)

    cameras = sub.add_parser("cameras", help="list the cameras the installed backends can reach")
    cameras.add_argument("--json", action="store_true", help="print the list as JSON")
    cameras.add_argument(
        "--timeout", type=float, default=30.0, help="seconds the backends may take to look (default 30)"
    )
    cameras.set_defaults(func=_cameras)

    clean = sub.add_parser("clean", help="remove shared memory left by a crashed service")
    clean.add_argument("--name", default=defaults.SERVICE, help=f"service name (default {defaults.SERVICE})")
    clean.set_defaults(func=_clean)
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return args.func(args)
    except FxisError as exc:
        print(f"fxis {args.command}: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
