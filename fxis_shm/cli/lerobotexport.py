"""``fxis export BAG --lerobot OUT --fps HZ``: the flags and the printed summary of a
LeRobot export (fxis_shm.record.lerobotexport does the work)."""

from __future__ import annotations

from fxis_shm.cli import exitcodes
from fxis_shm.errors import InvalidArgument


def lerobot_command(args) -> int:
    from fxis_shm.record.lerobotexport import export_lerobot

    if args.camera is not None or args.out is not None:
        raise InvalidArgument("--lerobot writes a dataset of every camera: leave out --camera and --out")
    if args.fps is None:
        raise InvalidArgument("--lerobot OUT needs --fps HZ (the dataset's frame rate)")
    done = export_lerobot(args.bag, args.lerobot, args.fps, args.max_skew_ms, args.task)
    grid = done.grid
    print(
        f"{done.out}: LeRobotDataset v3.0, 1 episode of {done.frames} frames at {done.fps} fps from cameras "
        f"{', '.join(done.cameras)}; {grid.dropped} of {grid.total} slots dropped (no tuple within "
        f"{done.max_skew_ms:g} ms: {grid.dropped_skew}; frames over half a slot from it: {grid.dropped_far}); "
        f"capture times in ns of {done.clock}"
    )
    print(f"{done.out}: observations only: the bag holds no robot state or action (no observation.state, no action)")
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
