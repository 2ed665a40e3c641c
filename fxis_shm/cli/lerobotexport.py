"""``fxis export BAG --lerobot OUT --fps HZ``: the flags and the printed summary of a
LeRobot export (fxis_shm.record.lerobotexport does the work)."""

from __future__ import annotations

from fxis_shm.cli import exitcodes
from fxis_shm.errors import InvalidArgument


def lerobot_command(args) -> int:
    from fxis_shm.record.lerobotexport import ExportOptions, export_lerobot

    if args.camera is not None or args.out is not None:
        raise InvalidArgument("--lerobot writes a dataset of every camera: leave out --camera and --out")
    if args.fps is None:
        raise InvalidArgument("--lerobot OUT needs --fps HZ (the dataset's frame rate)")
    options = ExportOptions(args.fps, args.max_skew_ms, args.task, args.state_topic, args.action_topic)
    done = export_lerobot(args.bag, args.lerobot, options)
    grid = done.grid
    print(
        f"{done.out}: LeRobotDataset v3.0, 1 episode of {done.frames} frames at {done.fps} fps from cameras "
        f"{', '.join(done.cameras)}; {grid.dropped} of {grid.total} slots dropped (no tuple within "
        f"{done.max_skew_ms:g} ms: {grid.dropped_skew}; frames over half a slot from it: {grid.dropped_far}; "
        f"no joint state near it: {grid.dropped_joints}); capture times in ns of {done.clock}"
    )
    if done.joints:
        said = "; ".join(f"{key} from {topic}" for key, topic in done.joints.items())
        print(f"{done.out}: {said} (joint positions)")
    else:
        print(
            f"{done.out}: observations only: the bag holds no sensor_msgs/msg/JointState "
            "(no observation.state, no action)"
        )
    return exitcodes.DONE


def add_arguments(export) -> None:
    export.add_argument(
        "--lerobot",
        metavar="OUT",
        help="write a LeRobotDataset v3.0 folder OUT (a new one) of every camera of the bag, resampled "
        "at --fps by fxis's joint selection (docs/lerobot.md)",
    )
    export.add_argument("--fps", type=float, metavar="HZ", help="with --lerobot: the dataset's frame rate (whole)")
    export.add_argument(
        "--max-skew-ms",
        type=float,
        metavar="MS",
        help="with --lerobot: a slot whose best tuple is more skewed than this is dropped (default: half a slot)",
    )
    export.add_argument("--task", metavar="TEXT", help="with --lerobot: the episode's task (default: the bag's name)")
    export.add_argument(
        "--state-topic",
        metavar="TOPIC",
        help="with --lerobot: the sensor_msgs/msg/JointState topic of observation.state (default: the bag's one)",
    )
    export.add_argument(
        "--action-topic", metavar="TOPIC", help="with --lerobot: the JointState topic of action (default: none)"
    )
