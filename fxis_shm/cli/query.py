"""``fxis status`` and ``fxis grab``: ask a running service."""

from __future__ import annotations

import json

from fxis_shm.cli.options import add_client_options, client_for, nanoseconds
from fxis_shm.cli.stopsignals import as_interrupts, interrupted
from fxis_shm.cli.table import aligned
from fxis_shm.core import timebase
from fxis_shm.service.rtpolicy import sched_text
from fxis_shm.shm.cameras import RATE_WINDOW_NS


def status_command(args) -> int:
    with client_for(args) as client:
        status = client.status()
        # this host's view of the service's clock (what a client here maps times with)
        status["clock_mapping"] = client.clock_estimate().as_dict()
    if args.json:
        print(json.dumps(status, indent=2))
        return 0
    print(
        f"service {status['service']!r}  uptime {status['uptime_s']:.1f} s  "
        f"requests {status['requests_served']}  waiting {status['pending']}  "
        f"ring ordering {status.get('ring_ordering', '-')}"
    )
    mapping = status["clock_mapping"]
    print(
        f"clock {timebase.WIRE_NAMES[timebase.of_status(status)]}: {mapping['method']}, offset from this host's "
        "CLOCK_MONOTONIC "
        f"{mapping['offset_ns'] / 1e6:+.3f} ms, drift {mapping['drift_ppm']:+.2f} ppm, "
        f"uncertainty {mapping['uncertainty_ns'] / 1e3:.0f} us"
    )
    window_s = RATE_WINDOW_NS / 1e9
    columns = [
        "camera",
        "kind",
        "alive",
        "shape",
        f"fps (last {window_s:g} s)",
        "set fps",
        "stored",
        "dropped",
        "age_ms",
        "slots",
        "history_s",
        "gen",
        "torn",
        "ptp",
    ]
    rows = []
    for name, cam in status["cameras"].items():
        shape = "x".join(map(str, cam.get("shape", []))) or "-"
        rows.append(
            [
                name,
                cam["kind"],
                "yes" if cam["alive"] else "NO",
                shape,
                _measured(cam, window_s),
                set_rate(cam),
                cam.get("frames_stored"),
                cam.get("frames_dropped"),
                _fixed(cam.get("last_frame_age_ms"), 1),
                cam.get("ring_slots"),
                cam.get("history_s"),
                cam.get("generation"),
                cam.get("torn_reads"),
                ptp_text(cam.get("ptp")),
            ]
        )
    cells = [columns] + [["-" if v is None else str(v) for v in r] for r in rows]
    print("\n".join(aligned(cells)))
    for name, cam in status["cameras"].items():
        if not cam["alive"] and cam.get("reason"):
            print(f"  {name}: {cam['reason']}")
        line = _sync_line(cam.get("sync"))
        if line:
            print(f"  {name}: {line}")
    processes = (status.get("supervisor") or {}).get("processes") or {}
    if processes:  # --realtime's doing (docs/deployment.md)
        print("scheduling: " + ", ".join(f"{key} {sched_text(p.get('sched'))}" for key, p in processes.items()))
    if status.get("ros2"):
        print("\n".join(_ros2_lines(status["ros2"])))
    return 0


def _sync_line(sync: dict | None) -> str | None:
    """How a camera was triggered for moments (docs/sync.md), once it has been."""
    if not sync or not (sync["latency_samples"] or sync["lockstep"]):
        return None
    line = (
        f"trigger latency {sync['trigger_latency_ms']:.3f} ms ({sync['latency_samples']} frames), "
        f"{sync['frames_scheduled']} captured at T, timer late p50 {sync['timer_late_p50_ms']:.3f} "
        f"p99 {sync['timer_late_p99_ms']:.3f} ms, {sync['triggers_missed']} missed"
    )
    grid = sync["lockstep"]
    if grid:
        line += (
            f"; lockstep {grid['hz']:g} Hz + {grid['phase_ms']:g} ms of {grid['clock']}: {grid['frames']} frames, "
            f"residual p50 {grid['residual_p50_ms']:.3f} p99 {grid['residual_p99_ms']:.3f} ms"
        )
    return line


def ptp_text(state: dict | None) -> str:
    """A camera's PTP state as its status gives it (fxis_shm.core.ptp.PtpState.as_status): "-"
    for a camera that cannot say (synthetic), "none" for one without PTP features."""
    if state is None:
        return "-"
    if not state.get("available"):
        return "none"
    if not state.get("enabled"):
        return "disabled"
    offset = "" if state.get("offset_ns") is None else f", offset {state['offset_ns']} ns"
    return f"{state.get('status') or 'unknown'}{' (locked)' if state.get('locked') else ''}{offset}"


def set_rate(cam: dict) -> str | None:
    """The camera's set fps; a camera that captures only on a trigger says so (its rate is the
    requests', not this one)."""
    rate = _fixed(cam.get("fps"), 3, "g")
    if cam.get("trigger") == "software":
        return f"{rate or '-'}, captures on request"
    return rate


def _fixed(value, decimals: int, kind: str = "f") -> str | None:
    """A figure with a fixed number of decimals (``g``: significant digits), or None."""
    return None if value is None else f"{value:.{decimals}{kind}}"


def _measured(cam: dict, window_s: float) -> str | None:
    """The measured rate; with its window when the ring held less than the column's."""
    fps, over = cam.get("measured_fps"), cam.get("measured_over_s") or 0.0
    if fps is None:
        return None
    return f"{fps:.1f}" if over >= window_s - 0.01 else f"{fps:.1f} ({over:.1f} s)"


def _ros2_lines(ros2: dict) -> list[str]:
    """What the ROS 2 bridge reported: frames published and skipped per camera, frames_at, and
    each topic some endpoint reads (or could not match, and why)."""
    cameras = ", ".join(f"{n} {c['published']} ({c['skipped']} skipped)" for n, c in ros2["cameras"].items())
    asked = ros2["frames_at"]
    lines = [
        f"ros2 via {ros2.get('via', 'cyclone')} on domain {ros2['domain']} under {ros2['namespace'] or '/'}: "
        f"published {cameras}; frames_at answered {asked['published']}, refused {asked['refused']}"
    ]
    for topic, match in (ros2.get("topics") or {}).items():
        if match["matched"] or match["refused"]:
            refused = f", {match['refused']} could not match: {'; '.join(match['why'])}" if match["refused"] else ""
            lines.append(f"  {topic}: {match['matched']} matched{refused}")
    return lines


def grab_command(args) -> int:
    from fxis_shm.cli.grabfiles import save_tuple
    from fxis_shm.client.snapshot import interrupted_by
    from fxis_shm.formats.outfolder import check_out_folder

    check_out_folder(args.out, "--out")
    cameras = args.cameras.split(",") if args.cameras else None
    try:
        with as_interrupts(), client_for(args) as client:
            frames = client.tuple(cameras=cameras, at=args.at)
    except KeyboardInterrupt as exc:
        return interrupted("grab", f"interrupted by {interrupted_by(exc)} before the tuple came: nothing saved")
    return save_tuple(args.out, frames)


def add_parsers(sub) -> None:
    status = sub.add_parser("status", help="show the cameras and the service")
    add_client_options(status)
    status.add_argument("--json", action="store_true", help="print the raw status as JSON")
    status.set_defaults(func=status_command)

    grab = sub.add_parser("grab", help="save one synchronized tuple as PNG files plus JSON metadata")
    add_client_options(grab)
    grab.add_argument("--out", required=True, metavar="DIR", help="folder to write into")
    grab.add_argument("--cameras", help="comma-separated cameras (default all)")
    grab.add_argument(
        "--at",
        type=nanoseconds,
        help="t* in ns of this host's CLOCK_MONOTONIC, mapped to the service's clock (default now)",
    )
    grab.set_defaults(func=grab_command)
