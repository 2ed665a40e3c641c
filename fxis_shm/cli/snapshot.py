"""``fxis snapshot``: what the cameras saw around a moment, into a rosbag2 bag
(fxis_shm.client.snapshot)."""

from __future__ import annotations

from fxis_shm.cli.options import add_client_options, client_for, nanoseconds, seconds
from fxis_shm.formats.outfolder import check_out_folder


def snapshot_command(args) -> int:
    check_out_folder(args.out, "--out")  # before a service is asked (issue 33)
    cameras = [c.strip() for c in args.cameras.split(",") if c.strip()] if args.cameras else None
    with client_for(args) as client:
        result = client.snapshot(args.at, args.before, args.after, args.out, cameras, args.encoding)
    for name, kept in result["cameras"].items():
        missing = kept["missing"]
        gone = (
            f", the ring no longer held the window's first {kept['gone_before_ms']:.0f} ms"
            if kept["gone_before_ms"]
            else ""
        )
        print(
            f"{name}: {kept['frames']} frames, {len(missing)} missing{f' (ids {missing[:10]})' * bool(missing)}{gone}"
        )
    print(f"wrote {result['out']}")
    incomplete = any(k["missing"] or k["gone_before_ms"] or not k["complete"] for k in result["cameras"].values())
    return 1 if incomplete else 0


def add_parser(sub) -> None:
    snapshot = sub.add_parser(
        "snapshot",
        help="every frame of the cameras in [t - before, t + after] into a rosbag2 bag (MCAP)",
        description="Keep what the cameras saw around a moment: the window's past from the rings at once, its "
        "future as the frames arrive, into a new rosbag2 folder (written as OUT.partial, renamed when complete). "
        "Stamps are capture times in this host's CLOCK_MONOTONIC. Exit status 1 if a frame of the window is "
        "missing (the bag's metadata lists it) or the rings no longer held the window's start.",
    )
    add_client_options(snapshot)
    snapshot.add_argument("--out", required=True, metavar="DIR", help="the bag folder to create (new, or empty)")
    snapshot.add_argument("--before", type=seconds, default=2.0, metavar="S", help="seconds before t (default 2)")
    snapshot.add_argument("--after", type=seconds, default=1.0, metavar="S", help="seconds after t (default 1)")
    snapshot.add_argument(
        "--at", type=nanoseconds, metavar="NS", help="t in ns of this host's CLOCK_MONOTONIC (default now)"
    )
    snapshot.add_argument("--cameras", metavar="A,B", help="comma-separated cameras (default all)")
    snapshot.add_argument("--encoding", choices=("raw", "jpeg"), default="raw", help="raw Image or JPEG (default raw)")
    snapshot.set_defaults(func=snapshot_command)
