"""``fxis view [ENDPOINT...] --rerun``: a running service, or a cell of several, live in Rerun
(fxis_shm.viewers.rerunview): into a viewer it starts, a viewer already running
(``--rerun-connect``), or an .rrd file (``--rerun-save``); docs/rerun.md."""

from __future__ import annotations

from fxis_shm.cli import exitcodes
from fxis_shm.cli.options import add_client_options, client_for, duration_seconds, milliseconds, ranged, rate_hz
from fxis_shm.cli.stopsignals import as_interrupts, interrupted
from fxis_shm.cli.syncreport import FALLBACK_RATE_HZ, chosen_cameras
from fxis_shm.core import syncstats
from fxis_shm.errors import InvalidArgument
from fxis_shm.wire import ranges

FLAG = "--rerun"


def view_command(args) -> int:
    from fxis_shm.formats.rerunlog import RerunLog, require_rerun
    from fxis_shm.record.rerunexport import check_new_file
    from fxis_shm.viewers.rerunview import LiveView

    require_rerun(FLAG)
    if args.rerun_save is not None and args.rerun_connect is not None:
        raise InvalidArgument("--rerun-save and --rerun-connect: give one (a file, or a running viewer)")
    if args.rerun_save is not None:
        check_new_file(args.rerun_save, "--rerun-save")
    endpoints = [*args.endpoints, *([args.endpoint] if args.endpoint else [])] if args.endpoints else None
    with as_interrupts(), client_for(args, endpoints) as client:
        status = client.status()
        cameras = chosen_cameras(args.cameras, status["cameras"])
        rates = [status["cameras"][n]["fps"] for n in cameras if status["cameras"][n].get("fps")]
        rate = args.rate or min(rates, default=FALLBACK_RATE_HZ)
        where = ", ".join(getattr(client, "endpoints", None) or [client.endpoint])
        log = RerunLog(FLAG, "monotonic", f"fxis view {where}")  # the client's clock: CLOCK_MONOTONIC
        sink = _open_sink(log, args)
        print(f"fxis view: {', '.join(cameras)} of {where} at {rate:g} Hz into {sink}", flush=True)
        try:
            ticks = None if args.tuples is None else int(args.tuples)
            viewed = LiveView(client, cameras, log, args.threshold_ms).run(rate, args.seconds, ticks)
        finally:
            log.close()
    print(f"fxis view: {viewed.describe()}")
    if viewed.interrupted:
        return interrupted("view", f"interrupted: {sink} holds what is above")
    return exitcodes.DONE


def _open_sink(log, args) -> str:
    if args.rerun_save is not None:
        log.save(args.rerun_save)
        return args.rerun_save
    if args.rerun_connect is not None:
        log.connect(args.rerun_connect)
        return f"the Rerun viewer at {args.rerun_connect}"
    log.spawn()
    return "a Rerun viewer (rerun, started)"


def add_parser(sub) -> None:
    view = sub.add_parser(
        "view",
        help="a running service, or a cell of several, live in Rerun (--rerun)",
        description="Every 1/--rate s, ask the newest joint tuple of the cameras and log into Rerun each "
        "camera's new frame as an image on the capture_time timeline (this host's CLOCK_MONOTONIC, ns) and the "
        "frame_id timeline, and the tuple's skew (sync/skew_ms) and verdict (sync/synced: 1 when complete and "
        "within --threshold-ms). Into a Rerun viewer it starts (the rerun-sdk package's `rerun`), a running "
        "one (--rerun-connect), or a file (--rerun-save). Runs until Ctrl-C, --seconds or --tuples. "
        "Needs the extra 'rerun' (pip install 'fxis-shm[rerun]').",
    )
    view.add_argument("endpoints", nargs="*", metavar="ENDPOINT", help="services (default: --endpoint's)")
    add_client_options(view)
    view.add_argument("--rerun", action="store_true", required=True, help="view in Rerun (the viewer fxis view has)")
    view.add_argument("--rerun-save", metavar="FILE.rrd", help="write an .rrd file (a new one) instead of a viewer")
    view.add_argument("--rerun-connect", metavar="URL", help="log to a running Rerun viewer, e.g. "
                      "rerun+http://127.0.0.1:9876/proxy")  # fmt: skip
    view.add_argument("--cameras", metavar="A,B", help="comma-separated cameras (default all)")
    view.add_argument("--rate", type=rate_hz, metavar="HZ", help="tuples per second (default: the slowest "
                      "camera's rate)")  # fmt: skip
    until = view.add_mutually_exclusive_group()
    until.add_argument(
        "--seconds", type=duration_seconds, metavar="S", help="stop after S seconds (default: at Ctrl-C)"
    )
    until.add_argument("--tuples", type=ranged(ranges.FRAMES), metavar="N", help="stop after asking N tuples "
                       "(default: at Ctrl-C)")  # fmt: skip
    view.add_argument("--threshold-ms", type=milliseconds, default=syncstats.DEFAULT_THRESHOLD_MS, metavar="X",
                      help="a tuple is synced when complete and its skew is at most this (default 3)")  # fmt: skip
    view.set_defaults(func=view_command)
