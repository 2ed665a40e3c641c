"""The ``fxis`` command: run, status, grab, clean."""
from __future__ import annotations

import argparse
import json
import logging
import os
import sys

from . import naming
from .client import Client
from .config import (DEFAULT_ENDPOINT, DEFAULT_FOXGLOVE_RATE_HZ, DEFAULT_HTTP, MAX_FOXGLOVE_RATE_HZ,
                     build_config, load_toml)
from .errors import ConfigError, FxisError

EXIT_USAGE = 2


def _run(args) -> int:
    from .supervisor import StartError, Supervisor

    try:
        file_values = load_toml(args.config) if args.config else {}
        config = build_config(file_values, {
            "name": args.name, "endpoint": args.endpoint, "pub": args.pub, "events": args.events,
            "slots": args.slots,
            "cameras": args.camera, "restart_limit": args.restart_limit,
            "log_level": args.log_level, "curve_secret": args.curve_secret,
            "curve_clients": args.curve_clients, "insecure_bind": args.insecure_bind or None,
            "http": args.http, "foxglove": args.foxglove, "foxglove_rate": args.foxglove_rate,
        })
    except ConfigError as exc:
        print(f"fxis run: {exc}", file=sys.stderr)
        return EXIT_USAGE
    logging.basicConfig(level=config.log_level,
                        format="%(asctime)s supervisor %(levelname)s %(message)s")
    try:
        return Supervisor(config).run()
    except StartError as exc:
        print(f"fxis run: {exc}", file=sys.stderr)
        return 1


def _status(args) -> int:
    with Client(args.endpoint, timeout=args.timeout) as client:
        status = client.status()
    if args.json:
        print(json.dumps(status, indent=2))
        return 0
    print(f"service {status['service']!r}  uptime {status['uptime_s']:.1f} s  "
          f"requests {status['requests_served']}  waiting {status['pending']}")
    columns = ["camera", "kind", "alive", "shape", "fps", "stored", "dropped", "age_ms",
               "slots", "gen", "torn"]
    rows = []
    for name, cam in status["cameras"].items():
        shape = "x".join(map(str, cam.get("shape", []))) or "-"
        rows.append([name, cam["kind"], "yes" if cam["alive"] else "NO", shape,
                     cam.get("fps"), cam.get("frames_stored"), cam.get("frames_dropped"),
                     cam.get("last_frame_age_ms"), cam.get("ring_slots"), cam.get("generation"),
                     cam.get("torn_reads")])
    cells = [columns] + [["-" if v is None else str(v) for v in r] for r in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(columns))]
    for row in cells:
        print("  ".join(v.ljust(w) for v, w in zip(row, widths)).rstrip())
    for name, cam in status["cameras"].items():
        if not cam["alive"] and cam.get("reason"):
            print(f"  {name}: {cam['reason']}")
    return 0


def _grab(args) -> int:
    from .tuplefiles import tuple_files

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
    print(f"saved {len(frames)} image(s) and tuple.json to {args.out} "
          f"(skew {frames.skew_ns / 1e6:.3f} ms)")
    return 0


def _keys(args) -> int:
    from .security import create_keys

    public, secret = create_keys(args.out, args.name)
    print(f"wrote {public} (public: give it to the other side) and {secret} (secret: keep it)")
    return 0


def _cameras(args) -> int:
    from .workers.backends import discover_all

    found, unavailable = discover_all()
    if args.json:
        print(json.dumps({"cameras": found, "unavailable": unavailable}, indent=2))
        return 0
    if found:
        rows = [["kind", "id (device=...)", "model", "format"]] + [
            [c["kind"], str(c["id"]), str(c.get("model", "-")), str(c.get("format", "-"))] for c in found]
        widths = [max(len(r[i]) for r in rows) for i in range(4)]
        for row in rows:
            print("  ".join(v.ljust(w) for v, w in zip(row, widths)).rstrip())
    else:
        print("no cameras found")
    for kind, why in unavailable.items():
        print(f"({kind}: not available: {why})")
    return 0


def _clean(args) -> int:
    from .supervisor import service_running

    if service_running(args.name):
        print(f"fxis clean: service {args.name!r} is running; stop it first", file=sys.stderr)
        return 1
    removed = naming.remove_leftovers(args.name)
    for path in removed:
        print(f"removed {path}")
    if not removed:
        print(f"nothing of service {args.name!r} left in {naming.SHM_DIR}")
    return 0


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="fxis", description="Multi-camera acquisition service: synchronized images on request.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = sub.add_parser("run", help="start the service (default: two synthetic cameras)",
                         description="Start camera workers and the coordinator; Ctrl-C stops them "
                                     "and removes their shared memory.")
    run.add_argument("--name", help="service name (default fxis); names its shared memory")
    run.add_argument("--camera", action="append", metavar="NAME=KIND[:key=value,...]",
                     help="a camera, e.g. left=synthetic:fps=30,phase_ms=5 (repeatable)")
    run.add_argument("--endpoint", help=f"request/reply endpoint (default {DEFAULT_ENDPOINT})")
    run.add_argument("--pub", help="publish endpoint (default tcp://127.0.0.1:5556)")
    run.add_argument("--events", help="endpoint receiving request events (default tcp://127.0.0.1:5557)")
    run.add_argument("--slots", type=int, help="frames held per camera ring (default 20)")
    run.add_argument("--config", metavar="FILE.toml", help="settings file (flags override it)")
    run.add_argument("--restart-limit", type=int, help="restarts of a crashed process before giving up (default 5)")
    run.add_argument("--log-level", help="DEBUG, INFO (default), WARNING or ERROR")
    run.add_argument("--curve-secret", metavar="FILE", help="the service's NAME.key_secret: CurveZMQ on every socket")
    run.add_argument("--curve-clients", metavar="DIR", help="folder of the public keys (.key) of the clients allowed in")
    run.add_argument("--insecure-bind", action="store_true",
                     help="allow endpoints reachable from other hosts without CurveZMQ (prints a warning)")
    run.add_argument("--http", metavar="HOST:PORT|off",
                     help=f"serve the live dashboard (pictures, rates, skew; docs/dashboard.md) here "
                          f"(default {DEFAULT_HTTP}); off: none. Another host's address needs "
                          "--insecure-bind: HTTP has no authentication")
    run.add_argument("--foxglove", metavar="HOST:PORT|off",
                     help="serve the cameras to the Foxglove app over its WebSocket protocol here, e.g. "
                          "127.0.0.1:8765 (default off; needs the foxglove extra). Another host's "
                          "address needs --insecure-bind: it has no authentication (docs/dashboard.md)")
    run.add_argument("--foxglove-rate", metavar="HZ",
                     help=f"pictures a second per camera to Foxglove, at most {MAX_FOXGLOVE_RATE_HZ:g} "
                          f"(default {DEFAULT_FOXGLOVE_RATE_HZ:g}); the app can change it live (parameter rate_hz)")
    run.set_defaults(func=_run)

    def client_args(sp):
        sp.add_argument("--endpoint", default=DEFAULT_ENDPOINT, help=f"service endpoint (default {DEFAULT_ENDPOINT})")
        sp.add_argument("--timeout", type=float, default=3.0, help="seconds to wait for the reply (default 3)")

    status = sub.add_parser("status", help="show the cameras and the service")
    client_args(status)
    status.add_argument("--json", action="store_true", help="print the raw status as JSON")
    status.set_defaults(func=_status)

    grab = sub.add_parser("grab", help="save one synchronized tuple as PNG files plus JSON metadata")
    client_args(grab)
    grab.add_argument("--out", required=True, metavar="DIR", help="folder to write into")
    grab.add_argument("--cameras", help="comma-separated cameras (default all)")
    grab.add_argument("--at", type=int, help="t* in ns of the service's CLOCK_MONOTONIC (default now)")
    grab.set_defaults(func=_grab)

    keys = sub.add_parser("keys", help="make a CurveZMQ key pair (for a service or a client)")
    keys.add_argument("--out", required=True, metavar="DIR", help="folder to write NAME.key and NAME.key_secret into")
    keys.add_argument("--name", default="fxis", help="file name of the pair (default fxis)")
    keys.set_defaults(func=_keys)

    cameras = sub.add_parser("cameras", help="list the cameras the installed backends can reach")
    cameras.add_argument("--json", action="store_true", help="print the list as JSON")
    cameras.set_defaults(func=_cameras)

    clean = sub.add_parser("clean", help="remove shared memory left by a crashed service")
    clean.add_argument("--name", default="fxis", help="service name (default fxis)")
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
