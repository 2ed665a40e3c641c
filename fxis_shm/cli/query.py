"""``fxis status`` and ``fxis grab``: ask a running service."""

from __future__ import annotations

import contextlib
import json
import os

from fxis_shm.cli.options import add_client_options, client_for, nanoseconds


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
        f"clock {status.get('clock', 'monotonic')}: {mapping['method']}, offset from this host's monotonic "
        f"{mapping['offset_ns'] / 1e6:+.3f} ms, drift {mapping['drift_ppm']:+.2f} ppm, "
        f"uncertainty {mapping['uncertainty_ns'] / 1e3:.0f} us"
    )
    columns = [
        "camera",
        "kind",
        "alive",
        "shape",
        "fps",
        "stored",
        "dropped",
        "age_ms",
        "slots",
        "history_s",
        "gen",
        "torn",
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
                cam.get("fps"),
                cam.get("frames_stored"),
                cam.get("frames_dropped"),
                cam.get("last_frame_age_ms"),
                cam.get("ring_slots"),
                cam.get("history_s"),
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
        print("\n".join(_ros2_lines(status["ros2"])))
    return 0


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
    from fxis_shm.formats.outfolder import check_out_folder
    from fxis_shm.formats.tuplefiles import tuple_files

    check_out_folder(args.out, "--out")
    cameras = args.cameras.split(",") if args.cameras else None
    with client_for(args) as client:
        frames = client.tuple(cameras=cameras, at=args.at)
    write_files(args.out, tuple_files(frames))
    print(f"saved {len(frames)} image(s) and tuple.json to {args.out} (skew {frames.skew_ns / 1e6:.3f} ms)")
    return 0


def write_files(folder: str, files: dict[str, bytes]) -> None:
    """``files`` into ``folder``, all or none: a write that fails (a full disk) removes what
    this call wrote, the folder too if it made it, and raises the OSError."""
    made = not os.path.isdir(folder)
    written: list[str] = []
    path = folder
    try:
        os.makedirs(folder, exist_ok=True)
        for name, data in files.items():
            path = os.path.join(folder, name)
            written.append(path)
            with open(path, "wb") as f:
                f.write(data)
    except OSError as exc:
        for done in written:
            with contextlib.suppress(OSError):
                os.remove(done)
        if made:
            with contextlib.suppress(OSError):
                os.rmdir(folder)
        raise OSError(exc.errno, f"{exc.strerror} (nothing was saved)", exc.filename or path) from None


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
