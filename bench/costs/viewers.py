"""Viewer cost: what watching the cameras costs the service, in CPU per process.

Launches a service of --cameras synthetic cameras and measures, over --seconds per stage,
the CPU time of each of its processes (supervisor, coordinator, every camera worker, the
dashboard; /proc/PID/stat) and of this script, in these stages:

  no dashboard   the service with --http off (the baseline)
  idle           the dashboard running, nobody looking (it samples the status twice a second)
  mjpeg xN       N viewers, each reading every camera's MJPEG stream at --fps (a page open)
  foxglove       a Foxglove WebSocket subscriber of every camera's pictures at --fps (where
                 this build has ``fxis run --foxglove`` and ``websockets`` is installed)
  ros2           ``fxis run --ros2`` with a ROS 2 subscriber (plain DDS, reliable, as
                 image_transport subscribes) of every camera's image_raw: every frame, not
                 --fps; it counts the frames that did not reach it (where cyclonedds is installed)

``--stages`` runs some of them; e.g. the bridge at the issue's load:
``viewers.py --stages "no dashboard" ros2 --cameras 4 --camera-fps 30``.

Also counts the frames each stage's viewers received, and the frames the cameras stored
and dropped, to show the viewers do not slow the cameras. Prints a table, writes
viewer_cost.json into --out. Exit status 0, 1 if a stage failed, 2 on bad flags.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import threading
import time
import urllib.request

import numpy as np

if not __package__:  # run as a script (python bench/costs/viewers.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common
from fxis_shm.service.launch import free_tcp_port
from fxis_shm.shm import procstat

BENCH = "bench (the viewers)"
FOXGLOVE_SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]  # foxglove-sdk >= 0.30, older
FOXGLOVE_MESSAGE_DATA = 0x01  # the opcode of a binary message carrying a channel's message


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    p.add_argument("--cameras", type=common.positive_int, default=2, help="synthetic cameras")
    p.add_argument("--camera-fps", type=common.positive_float, default=20.0, help="their frame rate")
    common.add_frame_size_args(p, 1360, 1024)
    p.add_argument("--fps", type=common.positive_float, default=10.0, help="rate each viewer asks for")
    p.add_argument("--preview-width", type=common.positive_int, default=640, help="width of the pictures viewers get")
    p.add_argument(
        "--viewers",
        type=common.positive_int,
        nargs="+",
        default=[1, 3],
        help="numbers of MJPEG viewers, one stage each",
    )
    p.add_argument("--seconds", type=common.positive_float, default=20.0, help="measuring time per stage")
    p.add_argument(
        "--warmup",
        type=common.nonnegative_float,
        default=2.0,
        help="seconds between starting a stage's viewers and measuring",
    )
    p.add_argument("--no-foxglove", action="store_true", help="leave out the Foxglove stage")
    p.add_argument(
        "--stages", nargs="+", metavar="STAGE", help='run only these ("no dashboard", idle, mjpeg, foxglove, ros2)'
    )
    common.add_output_args(p)
    return p


# ---- viewers (threads of this process) ----


class MjpegViewer(threading.Thread):
    """Reads one MJPEG stream as fast as it comes, counting its pictures."""

    def __init__(self, url: str, stop: threading.Event):
        super().__init__(daemon=True)
        self.url, self.stop, self.pictures, self.error = url, stop, 0, None

    def run(self) -> None:
        try:
            with urllib.request.urlopen(self.url, timeout=10) as answer:
                tail = b""
                while not self.stop.is_set():
                    chunk = answer.read1(1 << 16)
                    if not chunk:
                        raise ConnectionError("the stream ended")
                    data = tail + chunk
                    self.pictures += data.count(b"\r\nContent-Type: image/jpeg")
                    tail = data[-32:]  # a marker split across two reads is counted once
                    self.pictures -= tail.count(b"\r\nContent-Type: image/jpeg")
        except Exception as exc:  # reported in the results, the stage goes on
            self.error = common.describe_error(exc)


class FoxgloveViewer(threading.Thread):
    """Subscribes to one topic of a Foxglove WebSocket server (a camera's pictures), counting
    its messages. Connects as soon as the server listens (it starts after the service)."""

    def __init__(self, url: str, stop: threading.Event, topic: str, connect_timeout: float = 20.0):
        super().__init__(daemon=True)
        self.url, self.stop, self.topic, self.pictures, self.error = url, stop, topic, 0, None
        self.connect_timeout = connect_timeout

    def _connect(self):
        from websockets.sync.client import connect

        deadline = time.monotonic() + self.connect_timeout
        while True:
            try:
                return connect(self.url, subprotocols=FOXGLOVE_SUBPROTOCOLS, open_timeout=10, max_size=None)
            except ConnectionRefusedError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)

    def run(self) -> None:
        try:
            with self._connect() as ws:
                channel = None
                while channel is None:
                    message = ws.recv(timeout=10)
                    if isinstance(message, str) and json.loads(message).get("op") == "advertise":
                        channel = next((c for c in json.loads(message)["channels"] if c["topic"] == self.topic), None)
                ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 0, "channelId": channel["id"]}]}))
                while not self.stop.is_set():
                    with contextlib.suppress(TimeoutError):
                        message = ws.recv(timeout=1)
                        if isinstance(message, bytes) and message[0] == FOXGLOVE_MESSAGE_DATA:
                            self.pictures += 1
        except Exception as exc:
            self.error = common.describe_error(exc)


class Ros2Viewer(threading.Thread):
    """Subscribes to one camera's ``image_raw`` as a ROS 2 node would (reliable, keep last
    10), counting the images and the frame ids missing between them (the pixel stamp)."""

    def __init__(self, domain: int, topic: str, stop: threading.Event):
        super().__init__(daemon=True)
        self.domain, self.topic, self.stop = domain, topic, stop
        self.pictures = self.lost = 0
        self.error = None

    def run(self) -> None:
        from fxis_shm.formats import cdr
        from fxis_shm.formats.rosmsgs import IMAGE
        from fxis_shm.formats.stamp import read_stamp
        from fxis_shm.ros2.dds import RosParticipant

        last = None
        try:
            with RosParticipant(self.domain) as participant:
                reader = participant.raw_reader(self.topic, IMAGE)
                while not self.stop.is_set():
                    for data, _ in reader.wait_raw(0.2):
                        image = cdr.decode_image(data)
                        rows = np.frombuffer(image.data, np.uint8).reshape(image.height, image.step)
                        frame = read_stamp(rows)
                        self.lost += 0 if last is None or frame is None else max(0, frame - last - 1)
                        last, self.pictures = frame, self.pictures + 1
        except Exception as exc:
            self.error = common.describe_error(exc)


def ros2_available() -> str | None:
    """Why the ROS 2 stage cannot run here (None: it can)."""
    try:
        import cyclonedds  # noqa: F401
    except ImportError:
        return "the cyclonedds package is not installed (the ros2 extra)"
    return None


def foxglove_available() -> str | None:
    """Why the Foxglove stage cannot run here (None: it can)."""
    from fxis_shm.cli import parser as fxis_parser

    try:
        with contextlib.redirect_stderr(io.StringIO()):
            fxis_parser().parse_args(["run", "--foxglove", "127.0.0.1:1"])
    except SystemExit:
        return "this build of fxis has no --foxglove"
    try:
        import websockets.sync.client  # noqa: F401
    except ImportError:
        return "the websockets package is not installed (the test extra)"
    try:
        import foxglove  # noqa: F401
    except ImportError:
        return "the foxglove-sdk package is not installed (the foxglove extra)"
    return None


# ---- measuring ----


def processes(status: dict) -> dict[str, int]:
    """Label -> pid of every process of the service, and of this script."""
    sup = status["supervisor"]
    procs = {"supervisor": sup["pid"]}
    procs.update({key: p["pid"] for key, p in sup["processes"].items() if p["pid"]})
    procs[BENCH] = os.getpid()
    return procs


def cpu_seconds(procs: dict[str, int]) -> dict[str, float | None]:
    return {name: (lambda s: s and s.cpu_seconds)(procstat.read(pid)) for name, pid in procs.items()}


def camera_counts(status: dict) -> dict[str, tuple[int, int]]:
    return {n: (c.get("frames_stored") or 0, c.get("frames_dropped") or 0) for n, c in status["cameras"].items()}


def measure_stage(client, viewers: list, seconds: float, warmup: float) -> dict:
    """CPU % of one core per process, pictures per second per viewer, camera rates, over ``seconds``."""
    for v in viewers:
        v.start()
    time.sleep(warmup)  # streams connected and steady before the clock starts
    status = client.status()
    procs = processes(status)
    cpu0, cams0, pics0, t0 = cpu_seconds(procs), camera_counts(status), [v.pictures for v in viewers], time.monotonic()
    time.sleep(seconds)
    status = client.status()
    cpu1, cams1, pics1, t1 = cpu_seconds(procs), camera_counts(status), [v.pictures for v in viewers], time.monotonic()
    elapsed = t1 - t0
    cpu = {n: None if cpu0[n] is None or cpu1[n] is None else 100.0 * (cpu1[n] - cpu0[n]) / elapsed for n in procs}
    return {
        "seconds": elapsed,
        "cpu_percent": cpu,
        "viewer_pictures_per_s": [(b - a) / elapsed for a, b in zip(pics0, pics1)],
        "viewer_errors": [v.error for v in viewers if v.error],
        "viewer_lost": sum(getattr(v, "lost", 0) for v in viewers),
        "camera_fps": {n: (cams1[n][0] - cams0[n][0]) / elapsed for n in cams1 if n in cams0},
        "frames_dropped": {n: cams1[n][1] - cams0[n][1] for n in cams1 if n in cams0},
    }


def run_stage(name: str, run_args: list[str], make_viewers, args, out: str, http: str = "off") -> dict:
    """Launch a service, start the stage's viewers, measure, stop everything."""
    stop = threading.Event()
    with common.service(
        None, run_args, os.path.join(out, f"viewer_cost.{name.split()[0]}.log"), args.timeout, http=http
    ) as (client, _):
        common.wait_until_streaming(client)
        if http != "off":  # the dashboard starts after the coordinator answers
            common.wait_for_http(f"http://{http}/dashboard.json", timeout=20)
        viewers = make_viewers(stop)
        try:
            result = measure_stage(client, viewers, args.seconds, args.warmup)
        finally:
            stop.set()
            for v in viewers:
                v.join(10)
    print(f"  {name}: done", file=sys.stderr, flush=True)
    return {"stage": name, **result}


def stages(args, out: str) -> list[dict]:
    cams = [f"cam{i}" for i in range(args.cameras)]
    run_args = common.synthetic_camera_flags(cams, args.camera_fps, args.width, args.height)
    wanted = set(args.stages or ["no dashboard", "idle", "mjpeg", "foxglove", "ros2"])
    results = [run_stage("no dashboard", run_args, lambda stop: [], args, out)] if "no dashboard" in wanted else []
    http = f"127.0.0.1:{free_tcp_port()}"
    if "idle" in wanted:
        results.append(run_stage("idle", run_args, lambda stop: [], args, out, http))
    for n in args.viewers if "mjpeg" in wanted else []:
        urls = [f"http://{http}/cameras/{c}/stream.mjpg?fps={args.fps:g}&width={args.preview_width}" for c in cams]
        results.append(
            run_stage(
                f"mjpeg x{n}",
                run_args,
                lambda stop, n=n, urls=urls: [MjpegViewer(u, stop) for _ in range(n) for u in urls],
                args,
                out,
                http,
            )
        )
    if "ros2" in wanted:
        results.append(ros2_stage(cams, run_args, args, out))
    if "foxglove" not in wanted:
        return results
    why_not = "left out (--no-foxglove)" if args.no_foxglove else foxglove_available()
    if why_not is None:
        fox = f"127.0.0.1:{free_tcp_port()}"
        results.append(
            run_stage(
                "foxglove",
                run_args + ["--foxglove", fox, "--foxglove-rate", f"{args.fps:g}"],
                lambda stop: [FoxgloveViewer(f"ws://{fox}", stop, f"/{c}/image") for c in cams],
                args,
                out,
            )
        )
    else:
        results.append({"stage": "foxglove", "skipped": why_not})
    return results


def ros2_stage(cams: list[str], run_args: list[str], args, out: str) -> dict:
    why_not = ros2_available()
    if why_not is not None:
        return {"stage": "ros2", "skipped": why_not}
    from fxis_shm.ros2.loopback import loopback_config

    domain = 200 + os.getpid() % 30  # apart from the tests' (they hold their ids with lock files)
    os.environ["CYCLONEDDS_URI"] = loopback_config()  # this host only; the service inherits it
    return run_stage(
        "ros2",
        run_args + ["--ros2", "--ros2-domain", str(domain)],
        lambda stop: [Ros2Viewer(domain, f"/{c}/image_raw", stop) for c in cams],
        args,
        out,
    )


def report(results: list[dict], args) -> None:
    measured = [r for r in results if "cpu_percent" in r]
    names = []
    for r in measured:
        names += [n for n in r["cpu_percent"] if n not in names and not n.startswith("camera:") and n != BENCH]
    names.append(BENCH)
    rows = []
    for r in measured:
        cpu = r["cpu_percent"]
        cameras = sum(v for n, v in cpu.items() if n.startswith("camera:") and v is not None)
        pictures = r["viewer_pictures_per_s"]
        rows.append(
            [r["stage"]]
            + [cpu.get(n) for n in names]
            + [
                cameras,
                min(r["camera_fps"].values(), default=None),
                sum(r["frames_dropped"].values()),
                (sum(pictures) / len(pictures)) if pictures else None,
                r.get("viewer_lost"),
            ]
        )
    print(
        f"viewer_cost: {common.code_line(common.code_version())}; {args.cameras} camera(s) "
        f"{args.width}x{args.height} at {args.camera_fps:g} fps; viewers at {args.fps:g} fps, "
        f"{args.preview_width} px wide; {args.seconds:g} s per stage"
    )
    print(
        common.table(
            ["stage"] + names + ["cameras", "cam fps min", "dropped", "pics/s per stream", "lost"],
            rows,
            title="CPU % of one core per process",
            digits=1,
        )
    )
    for r in results:
        if r.get("skipped"):
            print(f"  {r['stage']}: skipped: {r['skipped']}")
        for error in r.get("viewer_errors", []):
            print(f"  {r['stage']}: a viewer failed: {error}")


def main(argv: list[str] | None = None) -> int:
    parsed = common.parse_args_and_out(parser(), argv)
    if isinstance(parsed, int):
        return parsed
    args, out = parsed
    results = stages(args, out)
    report(results, args)
    common.write_json(
        os.path.join(out, "viewer_cost.json"),
        {
            "settings": {k: v for k, v in vars(args).items() if k != "out"},
            "host": common.host_info(),
            "stages": results,
        },
    )
    failed = any(r.get("viewer_errors") for r in results)
    return common.EXIT_FAILED if failed else common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
