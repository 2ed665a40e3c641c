"""``fxis export BAG --camera NAME --out FILE.mp4``: a camera's video track of a bag into an
MP4 file, without re-encoding (fxis_shm.record.mp4export); ``fxis export BAG --rerun OUT.rrd``:
the whole bag as a Rerun recording (fxis_shm.record.rerunexport); ``fxis export BAG --lerobot OUT
--fps HZ``: the bag as a LeRobotDataset (fxis_shm.record.lerobotexport)."""

from __future__ import annotations

from fxis_shm.cli import exitcodes
from fxis_shm.errors import InvalidArgument


def export_command(args) -> int:
    if args.lerobot is not None:
        from fxis_shm.cli.lerobotexport import lerobot_command

        return lerobot_command(args)
    if args.rerun is not None:
        return rerun_command(args)
    if args.camera is None or args.out is None:
        raise InvalidArgument(
            "give --camera NAME --out FILE.mp4 (one camera's video as MP4), --rerun OUT.rrd (a Rerun recording) "
            "or --lerobot OUT --fps HZ (a dataset)"
        )
    from fxis_shm.record.mp4export import export_mp4

    done = export_mp4(args.bag, args.camera, args.out)
    skipped = f"; {done.skipped} messages before its first keyframe left out" if done.skipped else ""
    print(
        f"{done.out}: {done.frames} frames of {done.topic} ({done.codec}), {done.seconds:.3f} s, variable frame rate: "
        f"pts = capture time - {done.t0_ns} ns{skipped}; each frame's capture time and id in {done.sidecar}"
    )
    return exitcodes.DONE


def rerun_command(args) -> int:
    from fxis_shm.record.rerunexport import export_rerun

    if args.camera is not None or args.out is not None:
        raise InvalidArgument("--rerun writes every camera of the bag into OUT.rrd: give it without --camera and --out")
    print(export_rerun(args.bag, args.rerun).describe())
    return exitcodes.DONE


def add_parser(sub) -> None:
    export = sub.add_parser(
        "export",
        help="a camera's video track of a bag (fxis record --codec) into an MP4 file, without re-encoding; "
        "or the whole bag as a Rerun recording (--rerun) or a LeRobotDataset (--lerobot)",
        description="Copy the packets of BAG's /NAME/video (foxglove_msgs/CompressedVideo: h264, h265 or av1) "
        "into an MP4 file as they are, each frame presented at its capture time (a variable frame rate: pts "
        "in microseconds from the first frame's capture time, which the file's metadata names), and write "
        "FILE.frames.csv beside it: each frame's pts, capture time (ns), frame id and generation. Exit status 2, "
        "in one line, for a bag without that camera's video (the line names the cameras that have some), "
        "or an --out that exists. With --rerun OUT.rrd instead: every camera of the bag into a Rerun recording "
        "on a capture_time timeline (video packets as they are, images, each tuple's skew; docs/rerun.md). "
        "With --lerobot OUT --fps HZ instead: every camera of the bag (raw, JPEG or video) "
        "as a LeRobotDataset v3.0, one frame per slot of the grid t0 + k/fps that fxis's joint selection fills "
        "within --max-skew-ms (a slot it cannot fill is dropped and counted), each camera's true capture time "
        "beside it (docs/lerobot.md).",
    )
    export.add_argument("bag", metavar="BAG", help="the bag folder, or its .mcap file")
    export.add_argument("--camera", metavar="NAME", help="the camera whose /NAME/video to export")
    export.add_argument("--out", metavar="FILE.mp4", help="the MP4 file to write (a new one)")
    export.add_argument("--rerun", metavar="OUT.rrd", help="write the whole bag as this Rerun recording (a new file; "
                        "needs the extra 'rerun')")  # fmt: skip
    from fxis_shm.cli.lerobotexport import add_arguments

    add_arguments(export)
    export.set_defaults(func=export_command)
