"""``fxis record``: the cameras into a rosbag2 bag (fxis_shm.record.recorder)."""

from __future__ import annotations

from dataclasses import replace

from fxis_shm.cli import exitcodes
from fxis_shm.cli.options import EXIT_USAGE, add_client_options, client_for, duration_seconds, ranged, rate_hz
from fxis_shm.cli.stopsignals import as_interrupts, interrupted
from fxis_shm.cli.videoflags import add_encoding_option, add_video_options, video_settings
from fxis_shm.errors import ConfigError
from fxis_shm.formats.outfolder import check_out_folder
from fxis_shm.wire import ranges


def record_command(args) -> int:
    from fxis_shm.client.snapshot import interrupted_by
    from fxis_shm.record.recorder import Recorder, RecordSettings, summary_table
    from fxis_shm.wire import encoding

    def usage(message: str) -> int:
        exitcodes.say("record", message)
        return EXIT_USAGE

    if args.recover is not None:
        options = (("--cameras", args.cameras), ("--seconds", args.seconds), ("--frames", args.frames))
        options += (("--rate", args.rate), ("--quality", args.quality), ("--tuples", args.tuples or None))
        options += (("--codec", args.codec),)
        given = [flag for flag, value in options if value is not None]
        if given:
            return usage(f"--recover repairs a bag: it takes no {', '.join(given)}")
        return recover_command(args.recover)

    for flag, value in (("--seconds", args.seconds), ("--frames", args.frames), ("--rate", args.rate)):
        if value is not None and not value > 0:
            return usage(f"{flag} must be > 0, got {value}")
    if args.quality is not None and args.encoding != encoding.JPEG:
        return usage("--quality applies to --encoding jpeg only")
    if args.quality is not None and not 1 <= args.quality <= 100:
        return usage(f"--quality must be from 1 to 100, got {args.quality}")
    try:
        video = video_settings(args)
    except ConfigError as exc:
        return usage(str(exc))
    cameras = [c.strip() for c in args.cameras.split(",") if c.strip()] if args.cameras else None
    if args.cameras is not None and not cameras:
        return usage("--cameras names no camera")
    check_out_folder(args.out, "--out")  # before a service is asked (issue 33)
    settings = RecordSettings(
        out=args.out,
        endpoint=args.endpoint,
        cameras=cameras,
        seconds=args.seconds,
        frames=args.frames,
        rate_hz=args.rate,
        tuples=args.tuples,
        encoding=encoding.RAW if video else args.encoding,  # (--encoding h264 is video: --codec h264)
        quality=args.quality or encoding.DEFAULT_JPEG_QUALITY,
        video=video,
    )
    recorder = None
    try:
        with as_interrupts(), client_for(args) as client:
            settings = replace(settings, endpoint=client.endpoint)  # --endpoint's, or the config file's
            try:
                recorder = Recorder(settings, client)
            except ConfigError as exc:
                return usage(str(exc))
            summary = recorder.run()
    except KeyboardInterrupt as exc:  # before the recording's loop began, or a second Ctrl-C
        if recorder is None:
            return interrupted("record", f"interrupted by {interrupted_by(exc)} before recording began: no bag")
        recorder.bag.custom_data["ended"] = f"interrupted by {interrupted_by(exc)}"
        recorder.bag.close()  # (a no-op if the loop closed it)
        summary = recorder.summary()
        summary["interrupted_by"] = interrupted_by(exc)
    print(summary_table(summary))
    if summary["interrupted_by"]:
        return interrupted("record", f"interrupted by {summary['interrupted_by']}: {kept_line(summary)}")
    if summary.get("stopped_by"):  # a camera restarted as its video track cannot go on
        exitcodes.say("record", f"{summary['stopped_by']}: the recording stopped and {kept_line(summary)}")
        return exitcodes.FAILED
    if any(c["lost_to_restarts"] for c in summary["cameras"].values()):
        exitcodes.say("record", "done, but frames are missing where cameras restarted (above)")
        return exitcodes.MISSING
    return exitcodes.DONE


def kept_line(summary: dict) -> str:
    """What an interrupted or stopped recording kept, in one line."""
    frames = ", ".join(f"{cam} {c['frames']} frames" for cam, c in summary["cameras"].items())
    tuples = f", {summary['tuples']} tuples" if summary["tuples"] is not None else ""
    return f"kept {frames}{tuples}, {summary['seconds']:.1f} s, in {summary['out']}, a valid bag"


def recover_command(path: str) -> int:
    """``fxis record --recover DIR``: what was recovered and what was cut, on stdout."""
    from datetime import datetime, timezone

    from fxis_shm.formats.bagrecover import recover_bag

    done = recover_bag(path)
    if not done.wrote_metadata:
        print(f"{done.folder}: the bag is whole (its .mcap file has its summary and metadata.yaml is there)")
        return 0
    lines = [
        f"{done.file}: " + (f"no summary; {done.repair.describe()}" if done.repair else "metadata.yaml was missing")
    ]
    total = sum(n for _, n in done.topics.values())
    span = (done.end_time - done.start_time) / 1e9 if total else 0.0
    began = datetime.fromtimestamp(done.start_time / 1e9, timezone.utc).isoformat(timespec="milliseconds")
    lines.append(f"recovered {total} messages over {span:.3f} s" + (f" from {began} (log time)" if total else ""))
    width = max((len(t) for t in done.topics), default=0)
    lines += [f"  {topic.ljust(width)}  {count:6d}  {kind}" for topic, (kind, count) in done.topics.items()]
    if done.damaged:
        lines.append(f"the damaged original is kept as {done.damaged}")
    lines.append(f"{done.folder}: readable again (metadata.yaml written)")
    print("\n".join(lines))
    return 0


def add_parser(sub) -> None:
    record = sub.add_parser(
        "record",
        help="record the cameras into a rosbag2 bag (MCAP) for Foxglove, ros2 bag, rosbags",
        description="Record every frame of the cameras (or one synchronized tuple per step with "
        "--tuples) into a rosbag2 folder with MCAP storage: /NAME/image_raw "
        "(sensor_msgs/msg/Image) or /NAME/image_raw/compressed (JPEG), stamps in the "
        "service's clock (CLOCK_MONOTONIC unless fxis run --clock says otherwise). "
        "Ctrl-C or SIGTERM ends the recording with a valid bag (its metadata's 'ended' says "
        "'interrupted by SIGINT'), a line saying what it kept and exit code 130; so does a full disk, "
        "with a one-line error saying what the bag kept and exit code 4. "
        "Replay it with a camera of kind bag (docs/recording.md).",
    )
    add_client_options(record)
    bag = record.add_mutually_exclusive_group(required=True)
    bag.add_argument("--out", metavar="DIR", help="the bag folder to create (new, or empty)")
    bag.add_argument(
        "--recover",
        metavar="DIR",
        help="make a bag whose recording was killed (kill -9, a power cut) readable up to its last "
        "complete message, as ros2 bag reindex does; the damaged .mcap is kept as .mcap.damaged",
    )
    record.add_argument("--cameras", metavar="A,B", help="comma-separated cameras (default all)")
    until = record.add_mutually_exclusive_group()
    until.add_argument(
        "--seconds", type=duration_seconds, metavar="S", help="stop after S seconds (default: at Ctrl-C)"
    )
    until.add_argument(
        "--frames",
        type=ranged(ranges.FRAMES),
        metavar="N",
        help="stop after N frames per camera (N tuples with --tuples)",
    )
    record.add_argument(
        "--rate",
        type=rate_hz,
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
    add_encoding_option(record, "raw: sensor_msgs/Image (default); jpeg: sensor_msgs/CompressedImage")
    record.add_argument(
        "--quality", type=ranged(ranges.JPEG_QUALITY), metavar="Q", help="JPEG quality 1-100 (default 90)"
    )
    add_video_options(record, "record the frames")
    record.set_defaults(func=record_command)
