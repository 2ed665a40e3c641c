"""``fxis run``: the service, from flags and a config file, checked before anything starts."""

from __future__ import annotations

import argparse
import logging
import sys
import textwrap

from fxis_shm import _compiled
from fxis_shm.cli import exitcodes
from fxis_shm.core import timebase
from fxis_shm.errors import ConfigError
from fxis_shm.service.camerakinds import COMMON_OPTIONS, KINDS
from fxis_shm.service.config import DEFAULT_FOXGLOVE_RATE_HZ, MAX_FOXGLOVE_RATE_HZ, build_config, load_toml
from fxis_shm.service.rtpolicy import DEFAULT_PRIORITY, KERNEL_PRIORITY
from fxis_shm.wire import defaults


def run_command(args) -> int:
    from fxis_shm.service.addresses import check_free
    from fxis_shm.service.memory import check_room
    from fxis_shm.service.servicelock import service_running
    from fxis_shm.service.supervisor import Supervisor

    # every error below is one line and code 2 (fxis_shm.cli.main), before anything starts
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
            "restart_window_s": args.restart_window,
            "log_level": args.log_level,
            "curve_secret": args.curve_secret,
            "curve_clients": args.curve_clients,
            "curve_operators": args.curve_operators,
            "insecure_bind": args.insecure_bind or None,
            "clock": args.clock,
            "http": args.http,
            "foxglove": args.foxglove,
            "foxglove_rate": args.foxglove_rate,
            "viewer_token_file": args.viewer_token_file,
            "operator_token_file": args.operator_token_file,
            "viewer_tls_cert": args.viewer_tls_cert,
            "viewer_tls_key": args.viewer_tls_key,
            "ros2": args.ros2 or None,
            "ros2_domain": args.ros2_domain,
            "ros2_namespace": args.ros2_namespace,
            "ros2_tuples": args.ros2_tuples,
            "ros2_snapshots": args.ros2_snapshots,
            "ros2_via": args.ros2_via,
            "ros2_python": args.ros2_python,
            "ros2_settings": args.ros2_settings,
            "port_base": args.port_base,
            "history": args.history,
            "lockstep": args.lockstep,
            "lockstep_clock": args.lockstep_clock,
            "realtime": args.realtime,
        },
    )
    if config.realtime is not None:
        config = _realtime_granted(config)
    if service_running(config.name):  # its ports are in use too: say the more useful thing
        raise ConfigError(f"service {config.name!r} is already running (give --name another)")
    config, warnings = check_free(config)  # before anything starts: a port in use is one line
    check_room(config)  # and rings /dev/shm cannot hold
    for warning in warnings:
        print(f"fxis run: {warning}", file=sys.stderr)
    if _compiled.slow_unasked():  # here, where the hot path runs: no other command says it
        print(f"fxis run: {_compiled.slow_path_line()}", file=sys.stderr)
    logging.basicConfig(level=config.log_level, format="%(asctime)s supervisor %(levelname)s %(message)s")
    # a StartError is one line, after all was stopped and removed: code 2 if a camera refused its settings, else 4
    return exitcodes.DONE if Supervisor(config).run() == 0 else exitcodes.FAILED


def _realtime_granted(config):
    """The config as it can run: where SCHED_FIFO is refused, one line says so and the service runs
    at normal priority, or (require) it stops here with that line (code 2)."""
    from dataclasses import replace

    from fxis_shm.service import realtime

    why = realtime.refusal(config.realtime.priority)
    if why is None:
        if not realtime.memory_lockable():
            print(
                f"fxis run: --realtime: SCHED_FIFO {config.realtime.priority}, but {realtime.lock_refusal()}",
                file=sys.stderr,
            )
        return config
    if config.realtime.require:
        raise ConfigError(f"--realtime=require: {why}; not starting (docs/deployment.md says how to grant it)")
    print(f"fxis run: --realtime: {why}; running at normal priority (docs/deployment.md)", file=sys.stderr)
    return replace(config, realtime=None)


def _kinds_help() -> str:
    """The camera kinds --camera takes, and their keys (docs/cameras.md tells more)."""
    lines = [f"camera kinds (KIND) and their keys (any kind also takes {', '.join(COMMON_OPTIONS)}):"]
    for kind in KINDS.values():
        lines += [
            f"  {kind.name:<10} {kind.description}",
            *textwrap.wrap(", ".join(kind.options), 88, initial_indent=" " * 13, subsequent_indent=" " * 13),
        ]
    return "\n".join(lines)


def add_parser(sub) -> None:
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
        type=timebase.short_name,
        choices=tuple(timebase.CLOCK_IDS),
        help="the clock of every time the service gives and takes (default monotonic); "
        "realtime or tai where PTP or chrony keeps the cell's hosts in step; the POSIX names "
        "(CLOCK_MONOTONIC, the service's own spelling in what it says) are taken too "
        "(docs/deployment.md)",
    )
    run.add_argument(
        "--restart-limit",
        type=int,
        help=f"restarts of a crashed process within --restart-window before giving up, leaving it down "
        f"(default {defaults.RESTART_LIMIT})",
    )
    run.add_argument(
        "--restart-window",
        type=float,
        metavar="SECONDS",
        help=f"the restart limit counts the crashes of the last SECONDS; older ones are forgiven, so a process "
        f"that crashes now and then is always restarted (default {defaults.RESTART_WINDOW_S:g})",
    )
    run.add_argument("--log-level", help=f"DEBUG, INFO, WARNING or ERROR (default {defaults.LOG_LEVEL})")
    run.add_argument("--curve-secret", metavar="FILE", help="the service's NAME.key_secret: CurveZMQ on every socket")
    run.add_argument(
        "--curve-clients", metavar="DIR", help="folder of the public keys (.key) of the clients allowed in"
    )
    run.add_argument(
        "--curve-operators",
        metavar="DIR",
        help="folder of the public keys (.key) that may change camera settings (default: every client let in); "
        "they are let in too",
    )
    run.add_argument(
        "--insecure-bind",
        action="store_true",
        help="allow endpoints reachable from other hosts without CurveZMQ, and a dashboard or Foxglove server "
        "there without a token (prints a warning)",
    )
    run.add_argument(
        "--http",
        metavar="HOST:PORT|off",
        help=f"serve the live dashboard (pictures, rates, skew; docs/dashboard.md) here "
        f"(default {defaults.HTTP}); off: none. On an address other hosts reach it requires a "
        "token: the link to open is printed at start",
    )
    run.add_argument(
        "--foxglove",
        metavar="HOST:PORT|off",
        help="serve the cameras to the Foxglove app over its WebSocket protocol here, e.g. "
        "127.0.0.1:8765 (default off; needs the foxglove extra). On an address other hosts "
        "reach it requires a token, as the dashboard (docs/dashboard.md)",
    )
    run.add_argument(
        "--foxglove-rate",
        metavar="HZ",
        help=f"pictures a second per camera to Foxglove, at most {MAX_FOXGLOVE_RATE_HZ:g} "
        f"(default {DEFAULT_FOXGLOVE_RATE_HZ:g}); the app can change it live (parameter rate_hz)",
    )
    run.add_argument(
        "--viewer-token-file",
        metavar="FILE",
        help="the token the dashboard and the Foxglove server require (at least 16 characters of "
        "A-Z a-z 0-9 . _ ~ -), on every address, loopback too (default: a random one, printed at "
        "start, where other hosts reach them)",
    )
    run.add_argument(
        "--operator-token-file",
        metavar="FILE",
        help="the token the dashboard requires to change camera settings (not the viewer token); with "
        "--curve-operators and without it the dashboard only shows them (docs/security.md)",
    )
    run.add_argument(
        "--viewer-tls-cert",
        metavar="FILE",
        help="PEM certificate: the dashboard serves https and the Foxglove server wss (with --viewer-tls-key)",
    )
    run.add_argument("--viewer-tls-key", metavar="FILE", help="the PEM private key of --viewer-tls-cert")
    run.add_argument(
        "--history",
        metavar="SECONDS",
        help="seconds of frames each ring holds, sized from its camera's rate (instead of --slots; a camera's "
        "history= key wins)",
    )
    run.add_argument(
        "--lockstep",
        metavar="HZ[,PHASE_MS]",
        help="trigger every camera that can be triggered (trigger=software) on the grid k/HZ + PHASE_MS of "
        "--lockstep-clock (CLOCK_REALTIME by default), the cell's common clock: services on several hosts then "
        "capture together (docs/sync.md)",
    )
    run.add_argument(
        "--lockstep-clock",
        choices=("realtime", "tai"),
        help="the clock the --lockstep grid is counted in: realtime (default) or tai (PTP's timescale: no leap "
        "seconds; ptp4l + phc2sys keep it, with the kernel's TAI offset set)",
    )
    run.add_argument(
        "--realtime",
        nargs="?",
        const=True,
        metavar="PRIORITY|require",
        help=f"run the camera workers' threads and the coordinator's loop at SCHED_FIFO, memory locked: the "
        f"trigger timers at PRIORITY (default {DEFAULT_PRIORITY}, below the kernel's interrupt threads at "
        f"{KERNEL_PRIORITY}), the rest one below; where it is not allowed a line says so and the service runs "
        "at normal priority, or with require (also PRIORITY,require) does not start (docs/deployment.md)",
    )
    run.add_argument(
        "--port-base",
        type=int,
        metavar="N",
        help="every port from N: requests N, streams N+1, events N+2, dashboard N+3 (for a second "
        "service on this host; an address given explicitly still wins)",
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
    run.add_argument(
        "--ros2-snapshots",
        metavar="DIR",
        help="answer std_msgs/Header requests on NS/snapshot (stamp t, frame_id a bag name) with a snapshot of "
        "[t - 2 s, t + 1 s] into DIR/NAME (docs/ros2.md)",
    )
    run.add_argument(
        "--ros2-via",
        choices=("auto", "rclpy", "cyclone"),
        help="how the bridge publishes: rclpy (a ROS 2 node on the host's RMW: Fast DDS's shared memory for "
        "nodes on this host), cyclone (plain Cyclone DDS, no ROS install), auto (default): rclpy where it imports",
    )
    run.add_argument(
        "--ros2-python",
        metavar="PYTHON",
        help="run the bridge in this interpreter, one that imports rclpy and fxis_shm (a ROS 2 venv; docs/ros2.md)",
    )
    run.add_argument(
        "--ros2-settings",
        choices=("allow", "read"),
        help="whether nodes may change camera settings on NS/settings (allow) or only read them (read); "
        "default: read with --curve-operators (DDS has no keys), else allow",
    )
    run.set_defaults(func=run_command)
