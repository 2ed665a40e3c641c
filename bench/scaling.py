"""Scaling: how request latency and throughput grow with cameras, frame size and clients, and
the highest frame rate 4 cameras sustain without losing a frame while requests are served.

Every section launches its own `fxis run` services (synthetic mono8 cameras, rings of --slots,
tcp loopback, free ports), one at a time, each stopped before the next. A "past tuple" is
client.tuple(at=time.monotonic_ns() - 150 ms): t* lies in the past, its frames are stored, so
nothing is waited for (the bench and the service share CLOCK_MONOTONIC on one host). Timed
requests each follow a random sleep U[0, --sleep-max-ms] ms.

  cameras  --camera-counts services (1,2,3,4,6,8 cameras, 1360x1024 at --low-fps 10 fps, so
           that rendering does not saturate 2 cores); -n past tuples per transport (--paths):
           network = Client(local="off"), frames copied through the coordinator's socket;
           local = Client(local="require"), the shared-memory fast path. Reports median and
           p99 round trip, ms per camera, the service's own time (timing sent - received),
           and whether the latency grows no worse than linearly: latency(n) / latency(1) <= n
           (times 1.2 for noise) at every n > 1; the fitted exponent b of latency ~ n^b is
           shown too.
  size     2 cameras at --low-fps, --sizes 640x480 .. 4096x3072: the same measurement, with
           MB per tuple (1 MB = 10^6 bytes) and MB/s = MB per tuple / median round trip (what
           one client asking back to back would get).
  clients  2 cameras 1360x1024 at --clients-fps 20 fps, one service for the section:
           (a) --idle-counts extra connected clients (each did one status()) that then stay
           idle, while one client times -n past tuples: the latency should stay flat;
           (b) --active-counts clients that each ask past tuples back to back for
           --active-seconds, spread over up to --processes worker processes (threads in
           each, one Client per thread). Per count: median and p99 latency over every request,
           requests/s, frames/s and MB/s in total.
  fps      --fps-cameras 4 cameras 1360x1024 per --fps-steps frame rate (50 .. 300), a
           service each:
           after --warmup-seconds, --seconds of steady state during which a client asks
           client.tuple() (t* = now) every 1/--request-hz s (50 per second). A camera lost
           frames when its frames_dropped grew (the synthetic camera fell behind) or it
           stored fewer than fps * seconds - 2 frames. A step passes when no camera lost a
           frame and the requests were served at >= 90 % of --request-hz without a failure.
           The CPU share of every process of the service (supervisor, coordinator, camera
           workers, any other descendant) is read from /proc/<pid>/stat over the step:
           percent of one core; the total is out of 100 % x cores. The bench's own share and
           the rest of the host's (all cores' busy time from /proc/stat's idle counter, minus
           the service and the bench) are shown too: other load can make cameras fall behind.

The cameras and size sections measure each transport of --paths; the clients and fps
sections use --load-path (network by default: the coordinator copies every frame). The
local fast path needs a Client that takes local=; without it the local rows are skipped
with a note.

Targets (PASS/FAIL lines): latency grows no worse than linearly with cameras; latency is flat
with idle clients (median with the most idle clients <= 1.25 x median with none);
--fps-cameras cameras at --target-fps with no loss while serving --request-hz tuple requests
per second (judged on the step at --target-fps, or the next one above; other failed steps
are named).

Writes scaling.json (settings, every service's status, every request) and scaling.png (one
panel per section) into --out, and the services' logs (scaling.SECTION.service.log).
Exit status: 0 when the run completed (whatever the targets say); 1 if a service did not
start or stream, or a request of the cameras, size or clients sections failed (in the fps
section a failed request fails its step instead), or with --strict if a target failed; 2 on
bad flags.
"""
from __future__ import annotations

import argparse
import contextlib
import inspect
import math
import multiprocessing
import os
import random
import sys
import threading
import time

if __package__:
    from . import _common as common
else:  # run as a script, or loaded from its path
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import _common as common

from fxis_shm import Client, procstat
from fxis_shm.launch import ServiceProcess

SECTIONS = ("cameras", "size", "clients", "fps")
PATHS = ("network", "local")
LOCAL_OPTION = {"network": "off", "local": "require"}  # Client(local=...) per transport
PAST_NS = 150_000_000  # a past tuple's t* lies this far behind now
LINEAR_MARGIN = 1.2  # latency(n) / latency(1) may exceed n by this factor (noise)
IDLE_MARGIN = 1.25  # median with the most idle clients / median with none
FPS_EDGE_FRAMES = 2  # frames a step's window may miss at its edges
MIN_SERVED_SHARE = 0.9  # of --request-hz, for an fps step to pass
BUSY_HOST_PERCENT = 20.0  # CPU (% of a core) of other processes above which an fps step is flagged
MB = 1e6
BENCH, HOST, IDLE = "bench (client)", "host busy", "host idle"  # CPU rows besides the service's
WORKER_WAIT_S = 60.0  # longest a worker process of the active clients waits for its peers


# ---- command line ----------------------------------------------------------------------------

def int_list(text: str) -> list[int]:
    values = [int(v) for v in text.split(",") if v.strip()]
    if not values or min(values) < 0:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers >= 0, got {text!r}")
    return values


def positive_int_list(text: str) -> list[int]:
    values = int_list(text)
    if min(values) < 1:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers >= 1, got {text!r}")
    return values


def float_list(text: str) -> list[float]:
    values = [common.positive_float(v) for v in text.split(",") if v.strip()]
    if not values:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers > 0, got {text!r}")
    return values


def size_list(text: str) -> list[tuple[int, int]]:
    sizes = []
    for item in (v.strip() for v in text.split(",") if v.strip()):
        try:
            w, h = (int(x) for x in item.lower().split("x"))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {item!r}") from None
        if w < 1 or h < 1:
            raise argparse.ArgumentTypeError(f"a size must be at least 1x1, got {item!r}")
        sizes.append((w, h))
    if not sizes:
        raise argparse.ArgumentTypeError("no size given")
    return sizes


def name_list(choices: tuple[str, ...]):
    def parse(text: str) -> list[str]:
        names = [v.strip() for v in text.split(",") if v.strip()]
        unknown = [n for n in names if n not in choices]
        if unknown or not names:
            raise argparse.ArgumentTypeError(f"choose from {','.join(choices)}, got {text!r}")
        return [c for c in choices if c in names]
    return parse


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="scaling.py", description=__doc__, formatter_class=common.HelpFormatter)
    p.add_argument("--only", type=name_list(SECTIONS), default=",".join(SECTIONS), metavar="LIST",
                   help=f"sections to run, comma-separated, of {','.join(SECTIONS)}")
    p.add_argument("-n", "--requests", type=common.positive_int, default=200,
                   help="timed requests per point and transport (cameras, size, idle clients)")
    p.add_argument("--sleep-max-ms", type=common.nonnegative_float, default=10.0,
                   help="each timed request follows a sleep drawn from U[0, this] ms")
    p.add_argument("--warmup", type=int, default=5, help="unrecorded requests before each point")
    p.add_argument("--paths", type=name_list(PATHS), default=",".join(PATHS), metavar="LIST",
                   help="transports of the cameras and size sections: network (local=\"off\"), "
                        "local (local=\"require\", the shared-memory fast path)")
    p.add_argument("--load-path", choices=PATHS, default="network",
                   help="transport of the clients of the clients and fps sections")
    p.add_argument("--slots", type=common.positive_int, default=20, help="frames per camera ring")
    p.add_argument("--strict", action="store_true", help="exit with status 1 if a target failed")
    g = p.add_argument_group("cameras and size sections")
    g.add_argument("--camera-counts", type=positive_int_list, default="1,2,3,4,6,8", metavar="LIST",
                   help="camera counts of the cameras section (1360x1024)")
    g.add_argument("--sizes", type=size_list, default="640x480,1360x1024,2048x2048,4096x3072",
                   metavar="LIST", help="frame sizes WxH of the size section (2 cameras)")
    g.add_argument("--low-fps", type=common.positive_float, default=10.0,
                   help="frame rate of the cameras of these two sections")
    g = p.add_argument_group("clients section")
    g.add_argument("--idle-counts", type=int_list, default="0,1,4,16,64", metavar="LIST",
                   help="idle connected clients besides the one timing requests")
    g.add_argument("--active-counts", type=positive_int_list, default="1,2,4,8,16,32,64", metavar="LIST",
                   help="clients asking back to back at once")
    g.add_argument("--active-seconds", type=common.positive_float, default=4.0,
                   help="how long the active clients ask, per count")
    g.add_argument("--processes", type=common.positive_int, default=4,
                   help="worker processes the active clients are spread over")
    g.add_argument("--clients-fps", type=common.positive_float, default=20.0,
                   help="frame rate of the 2 cameras of the clients section")
    g = p.add_argument_group("fps section")
    g.add_argument("--fps-steps", type=float_list, default="50,75,100,125,150,200,250,300",
                   metavar="LIST", help="frame rates per camera to step through")
    g.add_argument("--seconds", type=common.positive_float, default=10.0, help="steady state per fps step")
    g.add_argument("--warmup-seconds", type=common.nonnegative_float, default=3.0,
                   help="before each step's steady state (the requests already run)")
    g.add_argument("--fps-cameras", type=common.positive_int, default=4, help="cameras (1360x1024) of the fps section")
    g.add_argument("--request-hz", type=common.positive_float, default=50.0,
                   help="client.tuple() requests per second during a step")
    g.add_argument("--target-fps", type=common.positive_float, default=100.0,
                   help="the frame rate the fps target asks for")
    common.add_output_args(p.add_argument_group("output"),
                           "folder for scaling.json, scaling.png and the service logs (files are overwritten)")
    return p


# ---- clients and requests --------------------------------------------------------------------

def local_supported() -> bool:
    """Whether this Client can choose its transport (the local= keyword)."""
    return "local" in inspect.signature(Client).parameters


def make_client(endpoint: str, timeout: float, path: str) -> Client:
    """A client on transport ``path`` (network or local)."""
    if local_supported():
        return Client(endpoint, timeout=timeout, local=LOCAL_OPTION[path])
    if path != "network":
        raise ValueError("this Client has no local= keyword: only the network path is available")
    return Client(endpoint, timeout=timeout)


def past_tuple(client: Client):
    return client.tuple(at=time.monotonic_ns() - PAST_NS)


def tuple_now(client: Client):
    return client.tuple()


def timed(client: Client, request=past_tuple) -> dict:
    """One request: round trip, the service's own time, the bytes and transport of the reply;
    a failure is recorded with its error, not raised."""
    t_send = time.monotonic_ns()
    try:
        reply = request(client)
    except common.REQUEST_ERRORS as exc:
        return {"t_send": t_send, "rtt_ns": time.monotonic_ns() - t_send, "error": common.describe_error(exc)}
    rtt = time.monotonic_ns() - t_send
    timing = reply.timing or {}
    return {
        "t_send": t_send, "rtt_ns": rtt, "error": None,
        "service_ns": timing["sent"] - timing["received"] if "sent" in timing and "received" in timing else None,
        "waited_ns": timing["waited"] - timing["received"] if "waited" in timing and "received" in timing else None,
        "bytes": sum(f.image.nbytes for f in reply.values()),
        "frames": len(reply),
        "path": getattr(reply, "path", None),
    }


def time_requests(client: Client, n: int, rng: random.Random, sleep_max_ms: float, warmup: int,
                  desc: str, request=past_tuple) -> list[dict]:
    """``warmup`` unrecorded then ``n`` timed requests, each after a random sleep."""
    for _ in range(warmup):
        timed(client, request)
    records = []
    with common.progress(n, desc) as bar:
        for _ in range(n):
            common.sleep_ms(rng.uniform(0.0, sleep_max_ms))
            records.append(timed(client, request))
            bar.update(1)
    return records


def latency_summary(records: list[dict]) -> dict:
    """Round trip and service time (ms), failures, bytes per reply, transports seen."""
    ok = [r for r in records if r["error"] is None]
    paths = {}
    for r in ok:
        paths[str(r.get("path"))] = paths.get(str(r.get("path")), 0) + 1
    return {
        "requests": len(records), "failed": len(records) - len(ok),
        "rtt_ms": common.summary(common.ms(r["rtt_ns"]) for r in ok),
        "service_ms": common.summary(common.ms(r["service_ns"]) for r in ok if r.get("service_ns") is not None),
        "waited": sum(1 for r in ok if (r.get("waited_ns") or 0) > 1_000_000),
        "bytes": max((r["bytes"] for r in ok), default=None),
        "paths": paths,
        "errors": sorted({r["error"] for r in records if r["error"]})[:5],
    }


# ---- services ----------------------------------------------------------------------------------

class Logs:
    """One log file per section; every service of the section appends to it."""

    def __init__(self, out: str):
        self.out = out

    def path(self, section: str) -> str:
        return os.path.join(self.out, f"scaling.{section}.service.log")

    def start(self, section: str) -> None:
        open(self.path(section), "wb").close()

    @contextlib.contextmanager
    def service(self, section: str, run_args: list[str], timeout: float):
        """A launched service (stopped on exit) and its status once every camera streams."""
        with open(self.path(section), "ab") as log:
            log.write(f"==== fxis run {' '.join(run_args)}\n".encode())
            log.flush()
            with ServiceProcess(run_args, stderr=log) as svc, svc.client(timeout=timeout) as client:
                status = common.wait_until_streaming(client, timeout=30.0)
                yield svc, status


def camera_args(n: int, fps: float, width: int, height: int, slots: int) -> list[str]:
    names = [f"cam{j}" for j in range(n)]
    return common.synthetic_camera_flags(names, fps, width, height) + ["--slots", str(slots)]


def measure_paths(args, endpoint: str, rng: random.Random, desc: str) -> dict:
    """-n past tuples per transport of --paths: path -> {summary, records}."""
    out = {}
    for path in usable_paths(args.paths):
        with make_client(endpoint, args.timeout, path) as client:
            records = time_requests(client, args.requests, rng, args.sleep_max_ms, args.warmup,
                                    f"{desc} {path}")
        out[path] = {"summary": latency_summary(records), "records": records}
    return out


def usable_paths(paths: list[str]) -> list[str]:
    return [p for p in paths if p == "network" or local_supported()]


def sanity_line(points: list[dict]) -> str:
    """Past tuples should never wait, and each reply should come on the transport asked for."""
    summaries = [(path, m["summary"]) for p in points for path, m in p["paths"].items()]
    waited = sum(s["waited"] for _, s in summaries)
    total = sum(s["requests"] - s["failed"] for _, s in summaries)
    other = sum(n for path, s in summaries for seen, n in s["paths"].items() if seen not in (path, "None"))
    return (f"past tuples that waited > 1 ms for a frame: {waited} of {total}; "
            f"replies on another transport than asked: {other}")


# ---- section: cameras ------------------------------------------------------------------------

def run_cameras(args, logs: Logs, rng: random.Random) -> dict:
    points = []
    for n in args.camera_counts:
        run_args = camera_args(n, args.low_fps, 1360, 1024, args.slots)
        with logs.service("cameras", run_args, args.timeout) as (svc, status):
            points.append({"cameras": n, "status": status,
                           "paths": measure_paths(args, svc.endpoint, rng, f"cameras {n}")})
    return {"points": points, "growth": {path: growth(points, path) for path in usable_paths(args.paths)}}


def growth(points: list[dict], path: str) -> dict:
    """Is median latency(n) / latency(1) <= n (x LINEAR_MARGIN) everywhere? And the exponent b."""
    pairs = [(p["cameras"], p["paths"][path]["summary"]["rtt_ms"]["median"]) for p in points
             if path in p["paths"] and p["paths"][path]["summary"]["rtt_ms"]["median"]]
    base = dict(pairs).get(1)
    if base is None or len(pairs) < 2:
        return {"passed": None, "why": "needs 1 camera and another count"}
    import numpy as np

    ratios = {n: m / base for n, m in pairs}
    worst_n = max((n for n in ratios if n > 1), key=lambda n: ratios[n] / n)
    exponent = float(np.polyfit(np.log([n for n, _ in pairs]), np.log([m for _, m in pairs]), 1)[0])
    return {"ratios": ratios, "worst_n": worst_n, "worst_ratio_per_n": ratios[worst_n] / worst_n,
            "exponent": exponent, "passed": ratios[worst_n] / worst_n <= LINEAR_MARGIN}


def report_cameras(result: dict) -> None:
    rows = []
    for p in result["points"]:
        for path, m in p["paths"].items():
            s = m["summary"]
            med = s["rtt_ms"]["median"]
            rows.append([f"{p['cameras']} cameras  {path}", s["requests"], s["failed"], med, s["rtt_ms"]["p99"],
                         med / p["cameras"] if med is not None else None, s["service_ms"]["median"],
                         (s["bytes"] or 0) / MB, result["growth"][path].get("ratios", {}).get(p["cameras"])])
    print(common.table(["cameras  path", "n", "failed", "median ms", "p99 ms", "ms/camera", "service ms",
                        "MB/tuple", "x latency(1)"], rows, digits=2,
                       title="cameras: past tuples, 1360x1024 mono8 cameras"))
    print(sanity_line(result["points"]))


# ---- section: size ---------------------------------------------------------------------------

def run_size(args, logs: Logs, rng: random.Random) -> dict:
    points = []
    for width, height in args.sizes:
        run_args = camera_args(2, args.low_fps, width, height, args.slots)
        with logs.service("size", run_args, args.timeout) as (svc, status):
            points.append({"width": width, "height": height, "status": status,
                           "paths": measure_paths(args, svc.endpoint, rng, f"size {width}x{height}")})
    return {"points": points}


def throughput_mb_s(summary: dict) -> float | None:
    med = summary["rtt_ms"]["median"]
    return summary["bytes"] / MB / (med / 1000) if med and summary["bytes"] else None


def report_size(result: dict) -> None:
    rows = []
    for p in result["points"]:
        for path, m in p["paths"].items():
            s = m["summary"]
            rows.append([f"{p['width']}x{p['height']}  {path}", s["requests"], s["failed"],
                         (s["bytes"] or 0) / MB, s["rtt_ms"]["median"], s["rtt_ms"]["p99"],
                         s["service_ms"]["median"], throughput_mb_s(s)])
    print(common.table(["size  path", "n", "failed", "MB/tuple", "median ms", "p99 ms", "service ms", "MB/s"],
                       rows, digits=2, title="size: past tuples of 2 mono8 cameras"))
    print(sanity_line(result["points"]))


# ---- section: clients ------------------------------------------------------------------------

def active_worker(conn) -> None:
    """Worker process of the active clients: on each task, ``threads`` clients connect, wait
    for the common start, ask past tuples back to back until the end, and report every request."""
    conn.send("up")
    while True:
        task = conn.recv()
        if task is None:
            return
        conn.send(_active_task(conn, task))


def _active_task(conn, task: dict) -> list[dict]:
    """One task of active_worker: the records of all its clients' requests."""
    records: list[list[dict]] = [[] for _ in range(task["threads"])]
    ready = threading.Barrier(task["threads"] + 1)
    window = {}
    go = threading.Event()

    def client_thread(j: int) -> None:
        with make_client(task["endpoint"], task["timeout"], task["path"]) as client:
            try:
                client.status()
            except common.REQUEST_ERRORS as exc:
                records[j].append({"t_send": time.monotonic_ns(), "rtt_ns": 0,
                                   "error": "connect: " + common.describe_error(exc)})
            ready.wait(WORKER_WAIT_S)
            if go.wait(WORKER_WAIT_S):
                time.sleep(max(0, window["start"] - time.monotonic_ns()) / 1e9)  # the common start
                while time.monotonic_ns() < window["end"]:
                    records[j].append(timed(client))

    threads = [threading.Thread(target=client_thread, args=(j,), daemon=True) for j in range(task["threads"])]
    for t in threads:
        t.start()
    ready.wait(WORKER_WAIT_S)
    conn.send("ready")
    window["start"], window["end"] = conn.recv()
    go.set()
    for t in threads:
        t.join()
    return [r for rs in records for r in rs]


class ActiveClients:
    """Up to ``processes`` spawned worker processes (no fork: the parent holds ZeroMQ sockets)."""

    def __init__(self, processes: int, timeout: float):
        self.timeout = timeout
        ctx = multiprocessing.get_context("spawn")
        self.workers = []
        for _ in range(processes):
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=active_worker, args=(child,), daemon=True)
            proc.start()
            child.close()
            self.workers.append((proc, parent))
        try:
            for _, conn in self.workers:
                self._receive(conn, WORKER_WAIT_S)  # "up": imported and listening
        except BaseException:
            self.close()
            raise

    def _receive(self, conn, timeout: float):
        if not conn.poll(timeout):
            raise RuntimeError(f"an active-client worker process did not answer within {timeout:.0f} s")
        return conn.recv()

    def run(self, endpoint: str, clients: int, seconds: float, path: str) -> tuple[list[dict], int, int]:
        """Every request of ``clients`` clients asking for ``seconds``; and the window (ns)."""
        used = self.workers[:min(clients, len(self.workers))]
        for k, (_, conn) in enumerate(used):
            share = clients // len(used) + (1 if k < clients % len(used) else 0)
            conn.send({"endpoint": endpoint, "timeout": self.timeout, "path": path, "threads": share})
        for _, conn in used:
            self._receive(conn, 30.0 + self.timeout)
        start = time.monotonic_ns() + 50_000_000
        end = start + int(seconds * 1e9)
        for _, conn in used:
            conn.send((start, end))
        records = []
        for _, conn in used:
            records += self._receive(conn, seconds + 2 * self.timeout + 30.0)
        return records, start, end

    def close(self) -> None:
        for _, conn in self.workers:
            with contextlib.suppress(OSError):
                conn.send(None)
        for proc, conn in self.workers:
            proc.join(5)
            if proc.is_alive():
                proc.terminate()
                proc.join(5)
            conn.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def run_clients(args, logs: Logs, rng: random.Random) -> dict:
    run_args = camera_args(2, args.clients_fps, 1360, 1024, args.slots)
    with ActiveClients(min(args.processes, max(args.active_counts)), args.timeout) as pool, \
            logs.service("clients", run_args, args.timeout) as (svc, status):
        idle = measure_idle(args, svc.endpoint, rng)
        active = [measure_active(args, pool, svc.endpoint, n) for n in args.active_counts]
    return {"status": status, "idle": idle, "active": active}


def measure_idle(args, endpoint: str, rng: random.Random) -> list[dict]:
    points, idle = [], []
    try:
        with make_client(endpoint, args.timeout, args.load_path) as client:
            for count in sorted(args.idle_counts):
                while len(idle) < count:
                    extra = make_client(endpoint, args.timeout, args.load_path)
                    idle.append(extra)
                    extra.status()  # really connected; from now on it stays idle
                records = time_requests(client, args.requests, rng, args.sleep_max_ms, args.warmup,
                                        f"idle clients {count}")
                points.append({"idle": count, "summary": latency_summary(records), "records": records})
    finally:
        for extra in idle:
            extra.close()
    return points


def measure_active(args, pool: ActiveClients, endpoint: str, clients: int) -> dict:
    records, start, end = pool.run(endpoint, clients, args.active_seconds, args.load_path)
    ok = [r for r in records if r["error"] is None]
    seconds = (max([r["t_send"] + r["rtt_ns"] for r in ok], default=end) - start) / 1e9
    summary = latency_summary(records)
    return {"clients": clients, "seconds": seconds, "summary": summary,
            "requests_per_s": len(ok) / seconds, "frames_per_s": sum(r["frames"] for r in ok) / seconds,
            "mb_per_s": sum(r["bytes"] for r in ok) / MB / seconds,
            "rtt_ms": [round(common.ms(r["rtt_ns"]), 3) for r in ok]}


def idle_flatness(idle: list[dict]) -> dict:
    meds = {p["idle"]: p["summary"]["rtt_ms"]["median"] for p in idle}
    if 0 not in meds or len(meds) < 2 or not meds[0]:
        return {"passed": None, "why": "needs 0 idle clients and another count"}
    most = max(meds)
    ratio = meds[most] / meds[0]
    return {"most": most, "median_ms": meds[most], "median_none_ms": meds[0], "ratio": ratio,
            "passed": ratio <= IDLE_MARGIN}


def report_clients(result: dict) -> None:
    rows = [[f"{p['idle']} idle", p["summary"]["requests"], p["summary"]["failed"],
             p["summary"]["rtt_ms"]["median"], p["summary"]["rtt_ms"]["p99"],
             p["summary"]["service_ms"]["median"]] for p in result["idle"]]
    print(common.table(["clients", "n", "failed", "median ms", "p99 ms", "service ms"], rows, digits=2,
                       title="clients (a): one client times past tuples while others stay idle "
                             "(2 cameras 1360x1024)"))
    rows = [[f"{p['clients']} active", p["summary"]["requests"], p["summary"]["failed"],
             p["summary"]["rtt_ms"]["median"], p["summary"]["rtt_ms"]["p99"], p["summary"]["service_ms"]["median"],
             p["requests_per_s"], p["frames_per_s"], p["mb_per_s"]] for p in result["active"]]
    print(common.table(["clients", "requests", "failed", "median ms", "p99 ms", "service ms", "req/s",
                        "frames/s", "MB/s"], rows, digits=1,
                       title="clients (b): every client asks past tuples back to back"))


# ---- section: fps ----------------------------------------------------------------------------

def service_processes(status: dict, supervisor_pid: int) -> dict[str, int]:
    """name -> pid of every process of the service: the supervisor, what it reports, the rest."""
    procs = {"supervisor": supervisor_pid}
    for name, proc in status["supervisor"]["processes"].items():
        if proc.get("pid"):
            procs[name] = proc["pid"]
    known = set(procs.values())
    for pid in procstat.descendants(supervisor_pid):
        if pid not in known:
            procs[f"other {pid}"] = pid
    return procs


def cpu_ticks(pid: int) -> int | None:
    """utime + stime of ``pid`` (every thread), in clock ticks; None if it is gone."""
    stat = procstat.read(pid)
    return None if stat is None else stat.cpu_ticks


def host_idle_ticks() -> int:
    """Clock ticks all CPUs of the host spent idle (idle + iowait). Busy time is taken as the
    rest: /proc/stat's user and system are sampled on timer ticks and miss periodic work that
    falls between them (4 cameras at 125 fps showed half their CPU), while idle is measured."""
    with open("/proc/stat") as f:
        idle, iowait = (int(v) for v in f.readline().split()[4:6])
    return idle + iowait


def cpu_sample(procs: dict[str, int]) -> dict:
    """CPU ticks so far of every named process, of the bench itself, and the host's idle ticks."""
    sample = {name: cpu_ticks(pid) for name, pid in procs.items()}
    sample[BENCH] = cpu_ticks(os.getpid())
    sample[IDLE] = host_idle_ticks()
    return sample


def cpu_percent(before: dict, after: dict, seconds: float) -> dict:
    """Percent of one core per process over ``seconds`` (None if it died meanwhile)."""
    tick = os.sysconf("SC_CLK_TCK")
    return {name: (after[name] - before[name]) / tick / seconds * 100
            if before.get(name) is not None and after.get(name) is not None else None for name in before}


class PacedRequester(threading.Thread):
    """client.tuple() every 1/hz s on its own client (no bursts to catch up)."""

    def __init__(self, endpoint: str, timeout: float, path: str, hz: float):
        super().__init__(daemon=True)
        self.endpoint, self.timeout, self.path, self.period = endpoint, timeout, path, 1.0 / hz
        self.records: list[dict] = []
        self.stopping = threading.Event()

    def run(self) -> None:
        with make_client(self.endpoint, self.timeout, self.path) as client:
            due = time.monotonic()
            while not self.stopping.is_set():
                self.records.append(timed(client, tuple_now))
                due += self.period
                delay = due - time.monotonic()
                if delay > 0:
                    self.stopping.wait(delay)
                else:
                    due = time.monotonic()

    def stop(self) -> None:
        self.stopping.set()
        self.join(self.timeout + 5)


def run_fps(args, logs: Logs, rng: random.Random) -> dict:
    steps = []
    with common.progress(len(args.fps_steps), "fps steps") as bar:
        bar.unit = "step"
        for fps in args.fps_steps:
            steps.append(measure_fps_step(args, logs, fps))
            bar.update(1)
    return {"steps": steps}


def measure_fps_step(args, logs: Logs, fps: float) -> dict:
    run_args = camera_args(args.fps_cameras, fps, 1360, 1024, args.slots)
    with logs.service("fps", run_args, args.timeout) as (svc, status), \
            svc.client(timeout=args.timeout) as client:
        requester = PacedRequester(svc.endpoint, args.timeout, args.load_path, args.request_hz)
        requester.start()
        try:
            time.sleep(args.warmup_seconds)
            procs = service_processes(client.status(), svc.proc.pid)
            cpu0 = cpu_sample(procs)
            s0, t0 = client.status(), time.monotonic_ns()
            time.sleep(args.seconds)
            s1, t1 = client.status(), time.monotonic_ns()
            cpu1 = cpu_sample(procs)
        finally:
            requester.stop()
    cpu = cpu_percent(cpu0, cpu1, (t1 - t0) / 1e9)
    cpu[HOST] = 100.0 * (os.cpu_count() or 1) - cpu.pop(IDLE)
    service = sum(cpu[name] for name in procs if cpu[name] is not None)
    requests = [r for r in requester.records if t0 <= r["t_send"] < t1]
    return fps_verdict({"fps": fps, "processes": procs, "cpu_percent": cpu, "cpu_total": service,
                        "cpu_others": cpu[HOST] - service - (cpu[BENCH] or 0.0),
                        "cameras": frame_counts(s0, s1, fps), "seconds": (t1 - t0) / 1e9,
                        "requests": latency_summary(requests), "records": requests,
                        "status_start": s0, "status_end": s1}, args.request_hz)


def frame_counts(s0: dict, s1: dict, fps: float) -> dict:
    """Per camera: frames expected from the service clock, stored and dropped between two statuses."""
    expected = fps * (s1["now"] - s0["now"]) / 1e9
    out = {}
    for cam, c1 in s1["cameras"].items():
        c0 = s0["cameras"][cam]
        stored = c1["frames_stored"] - c0["frames_stored"]
        dropped = c1["frames_dropped"] - c0["frames_dropped"]
        out[cam] = {"expected": expected, "stored": stored, "dropped": dropped,
                    "alive": c1["alive"] and c1["generation"] == c0["generation"],
                    "lost": dropped > 0 or stored < expected - FPS_EDGE_FRAMES or not c1["alive"]}
    return out


def fps_verdict(step: dict, hz: float) -> dict:
    req = step["requests"]
    step["request_hz"] = hz
    step["served_per_s"] = (req["requests"] - req["failed"]) / step["seconds"]
    step["no_loss"] = not any(c["lost"] for c in step["cameras"].values())
    step["passed"] = (step["no_loss"] and req["failed"] == 0 and step["served_per_s"] >= MIN_SERVED_SHARE * hz)
    return step


def report_fps(result: dict, args) -> None:
    rows = []
    for s in result["steps"]:
        cams = s["cameras"].values()
        expected = next(iter(cams))["expected"] if cams else None
        rows.append([f"{s['fps']:g}", expected, ",".join(str(c["stored"]) for c in cams),
                     ",".join(str(c["dropped"]) for c in cams), "yes" if s["no_loss"] else "NO",
                     s["requests"]["requests"], s["requests"]["failed"], s["served_per_s"],
                     s["requests"]["rtt_ms"]["median"], s["requests"]["rtt_ms"]["p99"], s["cpu_total"],
                     "PASS" if s["passed"] else "FAIL"])
    print(common.table(["fps", "expected", "stored per camera", "dropped per camera", "no loss", "requests",
                        "failed", "req/s", "median ms", "p99 ms", "service CPU %", "step"], rows, digits=1,
                       title=f"fps: {args.fps_cameras} cameras 1360x1024, {args.seconds:g} s per step, "
                             f"client.tuple() at {args.request_hz:g}/s ({args.load_path})"))
    names = []
    for s in result["steps"]:
        names += [n for n in s["cpu_percent"] if n not in names]
    names = [n for n in names if n not in (BENCH, HOST)]
    rows = [[f"{s['fps']:g}"] + [s["cpu_percent"].get(n) for n in names] +
            [s["cpu_total"], s["cpu_percent"][BENCH], s["cpu_others"], s["cpu_percent"][HOST]]
            for s in result["steps"]]
    print(common.table(["fps"] + names + ["service", "bench", "others", "host"], rows, digits=1,
                       separators=(len(names) + 1,),
                       title=f"CPU % of one core per process over each step (out of {100 * (os.cpu_count() or 1)} % "
                             "for all cores): service = its processes; bench = this client; others = the rest of "
                             "the host (host busy - service - bench)"))
    busy = [f"{s['fps']:g}" for s in result["steps"] if s["cpu_others"] > BUSY_HOST_PERCENT]
    if busy:
        print(f"note: other processes used more than {BUSY_HOST_PERCENT:g} % of a core during the steps at "
              f"{', '.join(busy)} fps: what they lost may be due to that load rather than to the service")


def fps_target(result: dict, args) -> dict:
    """Judged on the step at --target-fps (or the next step above it); the failed steps are named."""
    steps = result["steps"]
    best = max((s["fps"] for s in steps if s["passed"]), default=None)
    judged = min((s for s in steps if s["fps"] >= args.target_fps), key=lambda s: s["fps"], default=None)
    failed = {f"{s['fps']:g}": step_trouble(s) for s in steps if not s["passed"]}
    return {"highest_passing_fps": best, "judged_fps": judged and judged["fps"],
            "passed": judged["passed"] if judged else None, "failed_steps": failed}


def camera_lost(counts: dict) -> int:
    """Frames one camera lost in a step: dropped, or missing from what it stored, whichever is more."""
    return max(counts["dropped"], round(counts["expected"] - counts["stored"]), 0)


def step_trouble(step: dict) -> str:
    """What made an fps step fail, in a few words."""
    lost = sum(camera_lost(c) for c in step["cameras"].values())
    req = step["requests"]
    parts = [f"{lost} frames lost"] if not step["no_loss"] else []
    parts += [f"{req['failed']} requests failed"] if req["failed"] else []
    if step["served_per_s"] < MIN_SERVED_SHARE * step["request_hz"]:
        parts.append(f"{step['served_per_s']:.1f} req/s served")
    return ", ".join(parts)


# ---- figure ----------------------------------------------------------------------------------

def plot(results: dict, path: str, title: str, args) -> None:
    plt = common.pyplot()
    panels = [panel for section, section_panels in PANELS.items()
              if section in results and "error" not in results[section] for panel in section_panels]
    if not panels:
        return
    cols = 2 if len(panels) <= 4 else 3
    rows = math.ceil(len(panels) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.5 * cols, 4.6 * rows), squeeze=False)
    for ax, panel in zip(axes.flat, panels):
        panel(ax, results, args)
        ax.grid(True, alpha=0.3)
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plain_numbers(*axes_of) -> None:
    """Tick labels 2, 10, 64 rather than 2^1, 10^1 on log-scaled axes."""
    from matplotlib import ticker

    for axis in axes_of:
        axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
        axis.set_minor_formatter(ticker.NullFormatter())


def plot_cameras(ax, results, args) -> None:
    points = results["cameras"]["points"]
    for path in usable_paths(args.paths):
        n = [p["cameras"] for p in points]
        med = [p["paths"][path]["summary"]["rtt_ms"]["median"] for p in points]
        p99 = [p["paths"][path]["summary"]["rtt_ms"]["p99"] for p in points]
        line, = ax.plot(n, med, "o-", label=f"{path} median")
        ax.plot(n, p99, "^:", color=line.get_color(), label=f"{path} p99")
        base = dict(zip(n, med)).get(1)
        if base:
            ax.plot(n, [base * k for k in n], "--", color=line.get_color(), alpha=0.4,
                    label=f"{path}: latency(1) x n")
    ax.set_xlabel("cameras (1360x1024 mono8)")
    ax.set_ylabel("past tuple round trip, ms")
    ax.set_title("cameras")
    ax.legend(fontsize=7)


def plot_size(ax, results, args) -> None:
    points = results["size"]["points"]
    for path in usable_paths(args.paths):
        x = [(p["paths"][path]["summary"]["bytes"] or 0) / MB for p in points]
        y = [p["paths"][path]["summary"]["rtt_ms"]["median"] for p in points]
        ax.plot(x, y, "o-", label=f"{path} median")
        for p, xi, yi in zip(points, x, y):
            mbs = throughput_mb_s(p["paths"][path]["summary"])
            ax.annotate(f"{p['width']}x{p['height']}\n{common.fmt(mbs, 0)} MB/s", (xi, yi), fontsize=6,
                        textcoords="offset points", xytext=(4, -10))
    ax.set_xscale("log")
    ax.set_yscale("log")
    plain_numbers(ax.xaxis, ax.yaxis)
    ax.set_xlabel("MB per tuple (2 cameras, log)")
    ax.set_ylabel("past tuple round trip, ms (log)")
    ax.set_title("frame size")
    ax.legend(fontsize=7)


def plot_idle(ax, results, args) -> None:
    idle = results["clients"]["idle"]
    x = [p["idle"] for p in idle]
    ax.plot(x, [p["summary"]["rtt_ms"]["median"] for p in idle], "o-", label="median")
    ax.plot(x, [p["summary"]["rtt_ms"]["p99"] for p in idle], "^:", label="p99")
    ax.set_xscale("symlog", linthresh=1)
    ax.set_xticks(x)
    plain_numbers(ax.xaxis)
    ax.set_ylim(bottom=0)
    ax.set_xlabel("idle connected clients")
    ax.set_ylabel("past tuple round trip, ms")
    ax.set_title(f"clients (a): idle clients ({args.load_path})")
    ax.legend(fontsize=7)


def plot_active(ax, results, args) -> None:
    active = results["clients"]["active"]
    x = [p["clients"] for p in active]
    ax.plot(x, [p["summary"]["rtt_ms"]["median"] for p in active], "o-", label="median latency")
    ax.plot(x, [p["summary"]["rtt_ms"]["p99"] for p in active], "^:", label="p99 latency")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xticks(x)
    plain_numbers(ax.xaxis, ax.yaxis)
    ax.set_xlabel("active clients (back to back)")
    ax.set_ylabel("past tuple round trip, ms (log)")
    ax.legend(fontsize=7, loc="upper left")
    twin = ax.twinx()
    twin.plot(x, [p["requests_per_s"] for p in active], "s--", color="tab:green", label="requests/s")
    twin.set_ylabel("requests/s, all clients", color="tab:green")
    twin.set_ylim(bottom=0)
    twin.legend(fontsize=7, loc="lower right")
    ax.set_title(f"clients (b): active clients ({args.load_path})")


def plot_fps(ax, results, args) -> None:
    steps = results["fps"]["steps"]
    labels = [f"{s['fps']:g}" for s in steps]
    lost = [max(camera_lost(c) for c in s["cameras"].values()) for s in steps]
    ax.bar(labels, lost, color=["tab:green" if s["passed"] else "tab:red" for s in steps])
    for i, n in enumerate(lost):
        ax.annotate(str(n), (i, n), ha="center", textcoords="offset points", xytext=(0, 3), fontsize=8)
    ax.set_ylim(0, max(lost) * 1.25 + 1)
    ax.set_xlabel(f"fps per camera ({args.fps_cameras} cameras 1360x1024)")
    ax.set_ylabel("frames lost, worst camera (bar red: step failed)")
    twin = ax.twinx()
    twin.plot(labels, [s["requests"]["rtt_ms"]["p99"] for s in steps], "k^:", label="tuple p99 ms")
    twin.set_ylim(bottom=0)
    twin.set_ylabel("tuple request p99, ms")
    twin.legend(fontsize=7, loc="lower left")
    ax.set_title(f"fps: no loss while serving {args.request_hz:g} tuples/s")


def plot_cpu(ax, results, args) -> None:
    steps = results["fps"]["steps"]
    labels = [f"{s['fps']:g}" for s in steps]
    names = []
    for s in steps:
        names += [n for n in s["cpu_percent"] if n not in names and n not in (BENCH, HOST)]
    bottom = [0.0] * len(steps)
    for name in names:
        values = [s["cpu_percent"].get(name) or 0.0 for s in steps]
        ax.bar(labels, values, bottom=bottom, label=name)
        bottom = [b + v for b, v in zip(bottom, values)]
    ax.plot(labels, [s["cpu_percent"].get(BENCH) or 0.0 for s in steps], "kx--", label=BENCH)
    ax.plot(labels, [s["cpu_percent"][HOST] for s in steps], "ko-", mfc="none", label="host busy (all processes)")
    ax.axhline(100 * (os.cpu_count() or 1), color="red", lw=1, ls="--", label="all cores")
    ax.set_xlabel("fps per camera")
    ax.set_ylabel("CPU, % of one core")
    ax.set_title("CPU per service process during each fps step")
    ax.legend(fontsize=6, ncol=2)


# ---- main ------------------------------------------------------------------------------------

RUNNERS = {"cameras": run_cameras, "size": run_size, "clients": run_clients, "fps": run_fps}
PANELS = {"cameras": [plot_cameras], "size": [plot_size], "clients": [plot_idle, plot_active],
          "fps": [plot_fps, plot_cpu]}


def report(section: str, result: dict, args) -> None:
    if "error" in result:
        print(f"{section}: FAILED: {result['error']}")
    elif section == "cameras":
        report_cameras(result)
    elif section == "size":
        report_size(result)
    elif section == "clients":
        report_clients(result)
    else:
        report_fps(result, args)
    print(flush=True)


def targets(results: dict, args) -> list[dict]:
    out = []
    if "cameras" in results and "error" not in results["cameras"]:
        for path, g in results["cameras"]["growth"].items():
            detail = (f"worst latency(n)/latency(1) = {g['ratios'][g['worst_n']]:.2f} at n={g['worst_n']} "
                      f"(= {g['worst_ratio_per_n']:.2f} x n, limit {LINEAR_MARGIN:g} x n); fitted exponent "
                      f"b = {g['exponent']:.2f}" if "ratios" in g else g["why"])
            out.append({"target": f"latency grows no worse than linearly with cameras ({path})",
                        "passed": g["passed"], "detail": detail})
    if "clients" in results and "error" not in results["clients"]:
        f = idle_flatness(results["clients"]["idle"])
        detail = (f"median {f['median_ms']:.2f} ms with {f['most']} idle clients vs {f['median_none_ms']:.2f} ms "
                  f"with none: {f['ratio']:.2f}x (limit {IDLE_MARGIN:g}x)" if "ratio" in f else f["why"])
        out.append({"target": f"flat with idle clients ({args.load_path})", "passed": f["passed"], "detail": detail})
    if "fps" in results and "error" not in results["fps"]:
        t = fps_target(results["fps"], args)
        out.append({"target": f"{args.fps_cameras} cameras 1360x1024 at {args.target_fps:g} fps with no loss "
                              f"while serving {args.request_hz:g} tuple req/s",
                    "passed": t["passed"],
                    "detail": fps_detail(t, args)})
    return out


def fps_detail(t: dict, args) -> str:
    best = t["highest_passing_fps"]
    text = (f"step {t['judged_fps']:g} fps {'passed' if t['passed'] else 'failed'}; " if t["judged_fps"] else
            f"no step at or above {args.target_fps:g} fps; ")
    text += f"highest step with no loss: {f'{best:g} fps' if best else 'none'}"
    if t["failed_steps"]:
        text += "; failed steps: " + "; ".join(f"{fps} fps ({why})" for fps, why in t["failed_steps"].items())
    return text


def request_failures(results: dict) -> int:
    """Failed requests of the cameras, size and clients sections."""
    summaries = []
    for key in ("cameras", "size"):
        for p in results.get(key, {}).get("points", []):
            summaries += [m["summary"] for m in p["paths"].values()]
    clients = results.get("clients", {})
    summaries += [p["summary"] for p in clients.get("idle", []) + clients.get("active", [])]
    return sum(s["failed"] for s in summaries)


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = common.parse_args(p, argv)
    if isinstance(args, int):
        return args
    if args.load_path == "local" and not local_supported():
        return common.usage_error(p, "--load-path local needs a Client with the local= keyword")
    out = common.ensure_dir(args.out)
    rng = random.Random(args.seed)
    logs = Logs(out)
    host = common.host_info()  # before any service starts: the code it runs
    started = time.time()
    print(common.code_line(host["code"]))
    print(f"scaling: sections {','.join(args.only)}; {os.cpu_count()} CPUs; transports "
          f"{','.join(usable_paths(args.paths))}; timeout {args.timeout:g} s", flush=True)
    if "local" in args.paths and not local_supported():
        print("note: this Client has no local= keyword (the shared-memory fast path); "
              "the local transport is skipped, every request goes over the network path", flush=True)
    results: dict = {}
    json_path, png_path = os.path.join(out, "scaling.json"), os.path.join(out, "scaling.png")
    for section in args.only:
        logs.start(section)
        try:
            results[section] = RUNNERS[section](args, logs, rng)
        except (RuntimeError, OSError, EOFError, *common.REQUEST_ERRORS) as exc:
            results[section] = {"error": f"{type(exc).__name__}: {exc}"}
        report(section, results[section], args)
        document = {"benchmark": "scaling", "started_unix": started,
                    "argv": sys.argv[1:] if argv is None else list(argv),
                    "settings": vars(args), "host": host, "local_supported": local_supported(),
                    "clock": "CLOCK_MONOTONIC ns; t_send is the bench's time.monotonic_ns()",
                    "results": results}
        common.write_json(json_path, document)  # after every section: a crash keeps what was measured

    checks = targets(results, args)
    document["targets"] = checks
    common.write_json(json_path, document)
    print("targets:" if checks else "targets: none (they belong to the cameras, clients and fps sections)")
    for t in checks:
        verdict = {True: "PASS", False: "FAIL", None: "n/a"}[t["passed"]]
        print(f"  {verdict}  {t['target']}: {t['detail']}")
    failed = request_failures(results)
    broken = [s for s, r in results.items() if "error" in r]
    print(f"failed requests (cameras, size, clients): {failed}; sections that could not run: "
          f"{', '.join(broken) or 'none'}")
    plot(results, png_path, f"scaling ({os.cpu_count()} CPUs, {','.join(usable_paths(args.paths))})", args)
    print(f"wrote {json_path} and {png_path}")
    if failed or broken:
        return common.EXIT_FAILED
    if args.strict and any(t["passed"] is not True for t in checks):
        return common.EXIT_FAILED
    return common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
