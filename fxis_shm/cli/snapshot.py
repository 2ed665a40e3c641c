"""``fxis snapshot``: what the cameras saw around a moment, into a rosbag2 bag
(fxis_shm.client.snapshot)."""

from __future__ import annotations

import os

from fxis_shm.cli import exitcodes
from fxis_shm.cli.options import add_client_options, client_for, nanoseconds, seconds
from fxis_shm.cli.stopsignals import as_interrupts, interrupted
from fxis_shm.cli.videoflags import add_encoding_option, add_video_options, video_settings
from fxis_shm.errors import ConfigError, FxisError, InvalidArgument
from fxis_shm.formats.outfolder import check_out_folder
from fxis_shm.wire import encoding as image_encoding


def snapshot_command(args) -> int:
    from fxis_shm.client.snapshot import Interrupted, interrupted_by

    if args.recover is not None:
        return recover_command(args.recover)
    check_out_folder(args.out, "--out")  # before a service is asked (issue 33)
    cameras = [c.strip() for c in args.cameras.split(",") if c.strip()] if args.cameras else None
    try:
        video = video_settings(args)
        with as_interrupts(), client_for(args) as client:
            encoding = args.encoding if video is None else image_encoding.RAW
            result = client.snapshot(args.at, args.before, args.after, args.out, cameras, encoding, video=video)
    except (InvalidArgument, ConfigError) as exc:
        exitcodes.say("snapshot", exitcodes.message(exc))
        return exitcodes.USAGE
    except FxisError as exc:  # said by the command's error handler; what the bag kept, here
        for note in getattr(exc, "__notes__", []):
            exitcodes.say("snapshot", note)
        raise
    except Interrupted as exc:
        report(exc.result)
        return interrupted("snapshot", str(exc))
    except KeyboardInterrupt as exc:  # before the snapshot began (connecting): nothing to keep
        return interrupted("snapshot", f"interrupted by {interrupted_by(exc)} before the snapshot began: no bag")
    return report(result)


def report(result: dict) -> int:
    """A line per camera and one for the bag, on stdout; exit 1 if anything of the window is missing."""
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
    if result["out"] is None:
        print("no bag written: the rings held no frame of the window (ask for more history: fxis run --history)")
        return exitcodes.MISSING
    print(f"wrote {result['out']}")
    incomplete = any(k["missing"] or k["gone_before_ms"] or not k["complete"] for k in result["cameras"].values())
    return exitcodes.MISSING if incomplete else exitcodes.DONE


def recover_command(partial: str) -> int:
    """``fxis snapshot --recover OUT.partial``: the bag of a snapshot that was killed, made
    readable (as ``fxis record --recover``) and named ``OUT``."""
    from fxis_shm.cli.record import recover_command as recover_bag

    folder = os.path.normpath(partial)
    if not folder.endswith(".partial") or not os.path.isdir(folder):
        exitcodes.say("snapshot", f"--recover takes the OUT.partial folder a snapshot left, got {partial}")
        return exitcodes.USAGE
    out = folder[: -len(".partial")]
    if os.path.exists(out) and (not os.path.isdir(out) or os.listdir(out)):
        exitcodes.say("snapshot", f"{out} exists: move it away, then recover {folder} again")
        return exitcodes.USAGE
    done = recover_bag(folder)
    if done != exitcodes.DONE:
        return done
    os.rename(folder, out)
    print(f"{out}: the snapshot's bag (renamed from {folder})")
    return exitcodes.DONE


def add_parser(sub) -> None:
    snapshot = sub.add_parser(
        "snapshot",
        help="every frame of the cameras in [t - before, t + after] into a rosbag2 bag (MCAP)",
        description="Keep what the cameras saw around a moment: the window's past from the rings at once, its "
        "future as the frames arrive, into a new rosbag2 folder (written as OUT.partial, renamed when done). "
        "Stamps are capture times in this host's CLOCK_MONOTONIC. Exit status 1 if a frame of the window is "
        "missing (the bag's metadata lists it) or the rings no longer held the window's start (no bag at all if "
        "they held none of it); 130 if Ctrl-C or SIGTERM stopped it: the bag OUT then holds every frame copied "
        "until then, its metadata saying 'ended: interrupted'. A snapshot killed outright leaves OUT.partial: "
        "--recover OUT.partial makes it the bag OUT.",
    )
    add_client_options(snapshot)
    bag = snapshot.add_mutually_exclusive_group(required=True)
    bag.add_argument("--out", metavar="DIR", help="the bag folder to create (new, or empty)")
    bag.add_argument("--recover", metavar="OUT.partial", help="make the bag a killed snapshot left readable, named OUT")
    snapshot.add_argument("--before", type=seconds, default=2.0, metavar="S", help="seconds before t (default 2)")
    snapshot.add_argument("--after", type=seconds, default=1.0, metavar="S", help="seconds after t (default 1)")
    snapshot.add_argument(
        "--at", type=nanoseconds, metavar="NS", help="t in ns of this host's CLOCK_MONOTONIC (default now)"
    )
    snapshot.add_argument("--cameras", metavar="A,B", help="comma-separated cameras (default all)")
    add_encoding_option(snapshot, "raw Image or JPEG (default raw)")
    add_video_options(snapshot, "each camera's frames of the window (its first a keyframe)")
    snapshot.set_defaults(func=snapshot_command)
