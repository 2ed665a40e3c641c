"""Compare: what moving camera frames costs through this service versus the alternatives,
in one run, with the same frames for every contender.

Per scenario (--scenarios; default all: 2x1360x1024 = 2 synthetic mono8 cameras of 1360x1024,
4x1360x1024, 2x2048x2048) a service is launched (`fxis run`, the scenario's cameras at 20 fps,
rings of --slots, tcp loopback). Ten tuples are taken from it once (the "source": copies of
their frames, each tuple in its own arrays, cycled through so that the source is as cold as a
ring's slots) and then these contenders are timed, -n samples each after --warmup unrecorded
ones, INTERLEAVED: every round times one sample of each contender in a random order, after a
random sleep U[0, --sleep-max-ms] ms before each sample, so a drift of this machine's speed
hits all of them alike.

  fxis tuple tcp     Client(tcp, local="off").tuple(at=now - 150 ms): t* lies in the past, its
                     frames are stored, nothing is waited for (bench and service share
                     CLOCK_MONOTONIC on one host); the frames travel in the ZeroMQ reply.
  fxis tuple local   the same with local="require": the service replies with where the frames
                     are and the client copies them out of the shared-memory rings itself.
  imagezmq           an ImageHub in a child process receives and replies b"OK"; one sample =
                     the ImageSender sending the N frames of a source tuple (N sequential
                     send_image round trips, tcp loopback). Also shown per image (sample / N).
  imagezmq 1 image   the same with one image per sample (cycling through every source frame).
  mp.Queue           a child process that, for each request put on one multiprocessing.Queue,
                     puts the N frames of a source tuple (a list of arrays) on a reply queue;
                     one sample = request + get of the N frames.
  plain copy         the floor: frame.copy() of the N frames of a source tuple (fresh arrays,
                     which page-fault on first touch).
  copy reused        the other floor: np.copyto of the same frames into preallocated arrays.

Then the tcp service is stopped and the same cameras are served on an ipc endpoint
(ipc:///tmp/fxis-compare-<pid>.sock), where "fxis tuple ipc" (local="off") is timed, interleaved
with the plain copy again as a control of the machine's speed between the two phases.

Every fxis sample must come by the path asked for (FrameTuple.path), hold every camera, and
carry the synthetic cameras' pixel stamp (checked outside the timed call). A sample that
raises is recorded with its error and counted, never raised.

Prints one table per scenario (median and p99 in ms; "faults": the median count of minor page
faults the bench process took during a sample, which shows whether fresh arrays were faulted in
or came from memory the allocator had kept mapped; and the median's ratio to the plain copy,
to the reused-buffer copy, to imagezmq per tuple of N images and to imagezmq for ONE image),
then the targets, PASS/FAIL with their numbers:
  - tuple of 2 cameras over tcp: median <= 2x imagezmq's round trip for ONE image (scenario
    2x1360x1024, same run);
  - local fast path: median <= 1.5x the plain copy of the same bytes, against both floors.
Writes compare.json (settings, seed, host, every raw sample) and compare.png (median per
contender with p99 whiskers, one group per scenario) into --out, and the services' logs.
Exit status: 0 when every contender had answered samples (whatever the targets say); 1 if a
service did not start or stream, or every sample of some contender failed; 2 on bad flags.
"""
from __future__ import annotations

import argparse
import contextlib
import multiprocessing
import os
import queue
import random
import resource
import sys
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

if __package__:
    from . import _common as common
else:  # run as a script, or loaded from its path
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import _common as common

from fxis_shm import Client
from fxis_shm.launch import ServiceProcess, free_tcp_port

SCENARIOS = {"2x1360x1024": (2, 1360, 1024), "4x1360x1024": (4, 1360, 1024),
             "2x2048x2048": (2, 2048, 2048)}
TCP_TARGET_SCENARIO = "2x1360x1024"
FPS = 20.0
PAST_NS = 150_000_000  # t* of a timed tuple lies this far behind now: its frames are stored
SOURCE_TUPLES = 10
TCP_LIMIT = 2.0  # fxis tuple tcp / imagezmq 1 image
LOCAL_LIMIT = 1.5  # fxis tuple local / a plain copy
CHILD_START_S = 30.0

TCP, IPC, LOCAL = "fxis tuple tcp", "fxis tuple ipc", "fxis tuple local"
IMZ, IMZ_PER_IMAGE, IMZ_1 = "imagezmq", "imagezmq per image (sample / N)", "imagezmq 1 image"
MPQ, COPY, REUSED = "mp.Queue", "plain copy (fresh arrays)", "copy into reused buffers"
COPY_CONTROL = "plain copy, ipc phase (control)"
ROWS = (TCP, IPC, LOCAL, IMZ, IMZ_PER_IMAGE, IMZ_1, MPQ, COPY, REUSED)
PLOTTED = (TCP, IPC, LOCAL, IMZ, IMZ_1, MPQ, COPY, REUSED)


# ---- command line ----------------------------------------------------------------------------

def scenario_list(text: str) -> list[str]:
    names = [v.strip() for v in text.split(",") if v.strip()]
    unknown = [n for n in names if n not in SCENARIOS]
    if not names or unknown:
        raise argparse.ArgumentTypeError(f"expected a comma-separated subset of {', '.join(SCENARIOS)}, "
                                         f"got {text!r}")
    return list(dict.fromkeys(names))


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="compare.py", description=__doc__,
                                formatter_class=common.HelpFormatter)
    p.add_argument("-n", "--samples", type=common.positive_int, default=300,
                   help="measured samples of each contender per scenario")
    p.add_argument("--warmup", type=int, default=10, help="unrecorded samples of each contender first")
    p.add_argument("--scenarios", type=scenario_list, default=list(SCENARIOS),
                   help="comma-separated: " + ", ".join(SCENARIOS))
    p.add_argument("--sleep-max-ms", type=common.nonnegative_float, default=5.0,
                   help="each sample follows a sleep drawn from U[0, this] ms")
    p.add_argument("--slots", type=common.positive_int, default=20, help="frames per camera ring")
    common.add_output_args(p.add_argument_group("output"), seed_help="seed of the order and sleeps")
    return p


# ---- child processes: the imagezmq hub and the multiprocessing.Queue server -------------------

def hub_main(address: str, ready) -> None:
    """An ImageHub that answers every image with b"OK" (runs in a child process)."""
    import imagezmq

    hub = imagezmq.ImageHub(open_port=address)
    ready.set()
    while True:
        hub.recv_image()
        hub.send_reply(b"OK")


def queue_server_main(source: list[list[np.ndarray]], requests, replies, ready) -> None:
    """For each (id, k) request, puts (id, the frames of source tuple k) on ``replies``."""
    ready.set()
    while True:
        req = requests.get()
        if req is None:
            return
        req_id, k = req
        replies.put((req_id, source[k % len(source)]))


@contextlib.contextmanager
def child(ctx, target: Callable, *args) -> Any:
    """A daemon child process running ``target(*args, ready)``, started when it says it is
    ready, terminated (then killed) on exit whatever happened."""
    ready = ctx.Event()
    proc = ctx.Process(target=target, args=(*args, ready), daemon=True)
    proc.start()
    try:
        deadline = time.monotonic() + CHILD_START_S
        while not ready.wait(0.1):
            if proc.exitcode is not None:
                raise RuntimeError(f"{target.__name__} exited with code {proc.exitcode} during start-up")
            if time.monotonic() > deadline:
                raise RuntimeError(f"{target.__name__} did not start within {CHILD_START_S:.0f} s")
        yield proc
    finally:
        proc.terminate()
        proc.join(5)
        if proc.is_alive():
            proc.kill()
            proc.join(5)


class TimedSender:
    """imagezmq.ImageSender whose REQ socket gives up after ``timeout`` s (then it is rebuilt:
    a REQ socket that missed its reply cannot send again)."""

    def __init__(self, address: str, timeout: float):
        self.address, self.timeout = address, timeout
        self.sender = None
        self._open()

    def _open(self) -> None:
        import imagezmq
        import zmq

        self.sender = imagezmq.ImageSender(connect_to=self.address)
        for opt, value in ((zmq.RCVTIMEO, int(self.timeout * 1000)),
                           (zmq.SNDTIMEO, int(self.timeout * 1000)), (zmq.LINGER, 0)):
            self.sender.zmq_socket.setsockopt(opt, value)

    def send(self, images: list[np.ndarray]) -> None:
        import zmq

        for j, image in enumerate(images):
            try:
                reply = self.sender.send_image(f"cam{j}", image)
            except zmq.Again:
                self.close()
                self._open()
                raise TimeoutError(f"imagezmq hub gave no reply within {self.timeout:g} s") from None
            if reply != b"OK":
                raise RuntimeError(f"imagezmq hub replied {reply!r}")

    def close(self) -> None:
        if self.sender is not None:
            self.sender.close()
            self.sender = None


class QueueClient:
    """Asks the queue server for a source tuple; a late reply to an earlier request is skipped."""

    def __init__(self, requests, replies, timeout: float):
        self.requests, self.replies, self.timeout = requests, replies, timeout
        self._id = 0

    def get(self, k: int) -> list[np.ndarray]:
        self._id += 1
        self.requests.put((self._id, k))
        deadline = time.monotonic() + self.timeout
        while True:
            try:
                req_id, frames = self.replies.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise TimeoutError(f"mp.Queue server gave no reply within {self.timeout:g} s") from None
            if req_id == self._id:
                return frames


# ---- contenders and timing -------------------------------------------------------------------

@dataclass
class Contender:
    """``fn()`` is timed; ``check(result)`` runs afterwards, untimed, and raises if it is wrong."""

    name: str
    fn: Callable[[], Any]
    check: Callable[[Any], None] = lambda result: None
    samples: list = field(default_factory=list)  # ms, None for a failed sample
    faults: list = field(default_factory=list)  # minor page faults of this process per sample
    errors: list = field(default_factory=list)  # (sample index, error)
    first_traceback: str | None = None
    warmup_failed: int = 0


def minor_faults() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt


def time_once(c: Contender) -> tuple[float | None, int, str | None, str | None]:
    """One sample: (ms or None, minor page faults during the call, error or None, traceback
    or None); never raises."""
    f0 = minor_faults()
    try:
        t0 = time.perf_counter_ns()
        result = c.fn()
        elapsed = time.perf_counter_ns() - t0
        faults = minor_faults() - f0
        c.check(result)
        del result
        return elapsed / common.NS_PER_MS, faults, None, None
    except Exception as exc:  # recorded and counted, never raised
        return None, minor_faults() - f0, common.describe_error(exc), traceback.format_exc()


def record(c: Contender, sample: tuple) -> None:
    ms, faults, error, tb = sample
    c.samples.append(ms)
    c.faults.append(faults)
    if error is not None:
        c.errors.append((len(c.samples) - 1, error))
        c.first_traceback = c.first_traceback or tb


def time_contenders(contenders: list[Contender], n: int, warmup: int, rng: random.Random,
                    sleep_max_ms: float, desc: str) -> None:
    """``warmup`` then ``n`` rounds; each round one sample of every contender in a random order."""
    for _ in range(warmup):
        for c in contenders:
            c.warmup_failed += time_once(c)[2] is not None
    with common.progress(n * len(contenders), desc) as bar:
        for _ in range(n):
            for c in rng.sample(contenders, len(contenders)):
                common.sleep_ms(rng.uniform(0.0, sleep_max_ms))
                record(c, time_once(c))
                bar.update(1)


def cycle(items: list) -> Callable[[], Any]:
    """Returns the next of ``items`` on every call, round and round."""
    state = {"i": -1}

    def next_item():
        state["i"] = (state["i"] + 1) % len(items)
        return items[state["i"]]

    return next_item


def fxis_contender(name: str, client: Client, cameras: list[str], path: str) -> Contender:
    def fn():
        return client.tuple(at=time.monotonic_ns() - PAST_NS)

    def check(t):
        if t.path != path:
            raise AssertionError(f"the tuple came by the {t.path!r} path, not {path!r} as asked")
        if sorted(t) != sorted(cameras):
            raise AssertionError(f"the tuple holds {sorted(t)}, not {sorted(cameras)}")
        bad = [c for c in cameras if not common.stamp_ok(t[c], "synthetic")]
        if bad:
            raise AssertionError(f"pixel stamp does not match frame id for {bad}")

    return Contender(name, fn, check)


def frames_check(n: int, shape: tuple) -> Callable[[Any], None]:
    def check(images):
        if len(images) != n or any(im.shape != shape for im in images):
            raise AssertionError(f"got {len(images)} images of {[im.shape for im in images]}, "
                                 f"expected {n} of {shape}")
    return check


def copy_contenders(source: list[list[np.ndarray]], name: str = COPY) -> list[Contender]:
    """The two floors: fresh copies, and copies into buffers allocated (and faulted) once."""
    n, shape = len(source[0]), source[0][0].shape
    fresh_next, reused_next = cycle(source), cycle(source)
    dest = [np.zeros_like(f) for f in source[0]]

    def fresh():
        return [f.copy() for f in fresh_next()]

    def reused():
        for d, f in zip(dest, reused_next()):
            np.copyto(d, f)
        return dest

    return [Contender(name, fresh, frames_check(n, shape)),
            Contender(REUSED, reused, frames_check(n, shape))]


def imagezmq_contenders(sender: TimedSender, source: list[list[np.ndarray]]) -> list[Contender]:
    tuples_next = cycle(source)
    images_next = cycle([f for tup in source for f in tup])
    return [Contender(IMZ, lambda: sender.send(tuples_next())),
            Contender(IMZ_1, lambda: sender.send([images_next()]))]


def queue_contender(qc: QueueClient, source: list[list[np.ndarray]]) -> Contender:
    index_next = cycle(list(range(len(source))))
    return Contender(MPQ, lambda: qc.get(index_next()),
                     frames_check(len(source[0]), source[0][0].shape))


# ---- the services ----------------------------------------------------------------------------

def run_args_of(scenario: str, slots: int) -> tuple[list[str], list[str]]:
    n, width, height = SCENARIOS[scenario]
    names = [f"cam{j}" for j in range(n)]
    return names, common.synthetic_camera_flags(names, FPS, width, height) + ["--slots", str(slots)]


@contextlib.contextmanager
def launched(run_args: list[str], log_path: str, endpoint: str | None = None):
    """A ServiceProcess (stopped on exit) once its cameras stream, and its status then."""
    with open(log_path, "wb") as log, ServiceProcess(run_args, endpoint=endpoint, stderr=log) as svc:
        with svc.client(timeout=2.0) as client:
            status = common.wait_until_streaming(client, min_frames=SOURCE_TUPLES + 6)
        yield svc, status


def take_source(client: Client, cameras: list[str]) -> tuple[list[list[np.ndarray]], list[dict]]:
    """SOURCE_TUPLES consecutive stored tuples, each frame copied into its own array, and
    their frame ids."""
    tuples = client.sequence("consecutive", count=SOURCE_TUPLES, at=time.monotonic_ns() - PAST_NS)
    return ([[np.array(t[c].image, copy=True) for c in cameras] for t in tuples],
            [{c: t[c].frame_id for c in cameras} for t in tuples])


def tcp_phase(args, scenario: str, rng, out: str) -> tuple[list[Contender], dict, list]:
    """The service on tcp: every contender but ipc, interleaved. Returns the contenders, facts
    about the service and the source (for the ipc phase's control)."""
    cameras, run_args = run_args_of(scenario, args.slots)
    ctx = multiprocessing.get_context("spawn")  # no child inherits a ZeroMQ context
    log = os.path.join(out, f"compare.{scenario}.tcp.service.log")
    with contextlib.ExitStack() as stack:
        svc, status = stack.enter_context(launched(run_args, log))
        net = stack.enter_context(Client(svc.endpoint, timeout=args.timeout, local="off"))
        loc = stack.enter_context(Client(svc.endpoint, timeout=args.timeout, local="require"))
        source, source_ids = take_source(net, cameras)
        hub_address = f"tcp://127.0.0.1:{free_tcp_port()}"
        stack.enter_context(child(ctx, hub_main, hub_address))
        requests, replies = ctx.Queue(), ctx.Queue()
        stack.enter_context(child(ctx, queue_server_main, source, requests, replies))
        sender = TimedSender(hub_address, args.timeout)
        stack.callback(sender.close)
        contenders = [fxis_contender(TCP, net, cameras, "network"),
                      fxis_contender(LOCAL, loc, cameras, "local"),
                      *imagezmq_contenders(sender, source),
                      queue_contender(QueueClient(requests, replies, args.timeout), source),
                      *copy_contenders(source)]
        time_contenders(contenders, args.samples, args.warmup, rng, args.sleep_max_ms,
                        f"{scenario} tcp phase")
        info = {"endpoint": svc.endpoint, "log": log, "run_args": run_args, "status": status,
                "source_frame_ids": source_ids, "local_client_paths": dict(loc.paths)}
        requests.put(None)
    return contenders, info, source


def ipc_phase(args, scenario: str, rng, out: str, source) -> tuple[list[Contender], dict]:
    """The same cameras served on an ipc endpoint: fxis tuple ipc and the plain-copy control."""
    cameras, run_args = run_args_of(scenario, args.slots)
    sock_path = f"/tmp/fxis-compare-{os.getpid()}.sock"
    log = os.path.join(out, f"compare.{scenario}.ipc.service.log")
    try:
        with launched(run_args, log, endpoint=f"ipc://{sock_path}") as (svc, status), \
                Client(svc.endpoint, timeout=args.timeout, local="off") as client:
            contenders = [fxis_contender(IPC, client, cameras, "network"),
                          copy_contenders(source, COPY_CONTROL)[0]]
            time_contenders(contenders, args.samples, args.warmup, rng, args.sleep_max_ms,
                            f"{scenario} ipc phase")
            return contenders, {"endpoint": svc.endpoint, "log": log, "status": status}
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(sock_path)


# ---- results ---------------------------------------------------------------------------------

def result_of(c: Contender) -> dict:
    ok = [v for v in c.samples if v is not None]
    return {"summary_ms": common.summary(ok), "failed": len(c.errors), "warmup_failed": c.warmup_failed,
            "errors": c.errors[:20], "first_traceback": c.first_traceback,
            "minor_faults_median": float(np.median(c.faults)) if c.faults else None,
            "samples_ms": c.samples, "minor_faults": c.faults}


def per_image(result: dict, n: int) -> dict:
    """imagezmq's N-image samples divided by N."""
    samples = [v / n if v is not None else None for v in result["samples_ms"]]
    return {**result, "summary_ms": common.summary(v for v in samples if v is not None),
            "samples_ms": samples, "derived": f"{IMZ} samples / {n}"}


def median(results: dict, name: str) -> float | None:
    r = results.get(name)
    return r["summary_ms"]["median"] if r else None


def ratio(a: float | None, b: float | None) -> float | None:
    return a / b if a is not None and b else None


def scenario_table(scenario: str, results: dict, n_cams: int) -> str:
    refs = (COPY, REUSED, IMZ, IMZ_1)
    rows = []
    for name in ROWS:
        if name not in results:
            continue
        s, m = results[name]["summary_ms"], median(results, name)
        faults = results[name].get("minor_faults_median")
        rows.append([name, s["n"], results[name]["failed"], s["median"], s["p99"],
                     "-" if faults is None else f"{faults:.0f}",
                     *(ratio(m, median(results, ref)) for ref in refs)])
    _, w, h = SCENARIOS[scenario]
    mb = n_cams * w * h / 1e6
    return common.table(
        ["contender", "ok", "failed", "median ms", "p99 ms", "faults", "x copy", "x reused",
         f"x imagezmq({n_cams})", "x imagezmq(1)"],
        rows, title=f"{scenario}: {n_cams} cameras {w}x{h} mono8, {mb:.2f} MB per tuple",
        digits=3, separators=(6,))


def targets(all_results: dict) -> list[dict]:
    """The target checks, each with its numbers and a PASS/FAIL (None: not measurable)."""
    out = []
    res = all_results.get(TCP_TARGET_SCENARIO)
    tcp, one = (median(res, TCP), median(res, IMZ_1)) if res else (None, None)
    r = ratio(tcp, one)
    out.append({"target": f"tuple of 2 cameras over tcp: median <= {TCP_LIMIT:g}x imagezmq's round trip "
                          f"for ONE image (same run, {TCP_TARGET_SCENARIO})",
                "scenario": TCP_TARGET_SCENARIO, "median_ms": tcp, "reference_ms": one, "ratio": r,
                "limit": TCP_LIMIT, "pass": None if r is None else r <= TCP_LIMIT,
                "detail": (f"{TCP} {common.fmt(tcp, 3)} ms, {IMZ_1} {common.fmt(one, 3)} ms"
                           if res else f"scenario {TCP_TARGET_SCENARIO} not run")})
    for scenario, res in all_results.items():
        loc = median(res, LOCAL)
        for floor in (COPY, REUSED):
            ref = median(res, floor)
            r = ratio(loc, ref)
            out.append({"target": f"local fast path: median <= {LOCAL_LIMIT:g}x the plain copy of the same "
                                  f"bytes ({scenario}, floor: {floor})",
                        "scenario": scenario, "floor": floor, "median_ms": loc, "reference_ms": ref,
                        "ratio": r, "limit": LOCAL_LIMIT, "pass": None if r is None else r <= LOCAL_LIMIT,
                        "detail": f"{LOCAL} {common.fmt(loc, 3)} ms, {floor} {common.fmt(ref, 3)} ms"})
    return out


def verdict(t: dict) -> str:
    return {True: "PASS", False: "FAIL", None: "n/a "}[t["pass"]]


def print_targets(tlist: list[dict]) -> None:
    print("targets")
    for t in tlist:
        print(f"  {verdict(t)}  {t['target']}: {t['detail']}, ratio {common.fmt(t['ratio'], 2)}")
    by_scenario: dict[str, list[str]] = {}
    for t in tlist:
        if "floor" in t and t["pass"]:
            by_scenario.setdefault(t["scenario"], []).append(t["floor"])
    for scenario in dict.fromkeys(t["scenario"] for t in tlist if "floor" in t):
        checks = [t for t in tlist if t.get("floor") and t["scenario"] == scenario]
        passing = by_scenario.get(scenario, [])
        print(f"  local fast path, {scenario}: " + (
            "not measured" if all(t["pass"] is None for t in checks) else
            "passes against " + (" and ".join(passing) if passing else "neither floor")))


def plot(all_results: dict, path: str, title: str) -> None:
    plt = common.pyplot()
    from matplotlib import ticker

    scenarios = list(all_results)
    names = [n for n in PLOTTED if any(n in r for r in all_results.values())]
    width = 0.8 / len(names)
    fig, ax = plt.subplots(figsize=(max(9, 4 * len(scenarios)), 6))
    colors = plt.get_cmap("tab10").colors
    labels, lowest, highest = [], float("inf"), 0.0
    for j, name in enumerate(names):
        xs, meds, ups = [], [], []
        for i, scenario in enumerate(scenarios):
            s = all_results[scenario].get(name, {}).get("summary_ms")
            if s and s["median"] is not None:
                xs.append(i + (j - (len(names) - 1) / 2) * width)
                meds.append(s["median"])
                ups.append(s["p99"] - s["median"])
        ax.bar(xs, meds, width * 0.92, color=colors[j % len(colors)], label=name,
               yerr=[np.zeros(len(ups)), ups], capsize=2, error_kw={"elinewidth": 0.8})
        labels += [(x, m) for x, m in zip(xs, meds)]
        lowest, highest = min([lowest, *meds]), max([highest, *(m + u for m, u in zip(meds, ups))])
    ax.set_yscale("log")
    bottom = lowest / 3
    ax.set_ylim(bottom, highest * 8)  # room for the legend above the whiskers
    for x, m in labels:  # the median, written at the foot of its bar
        ax.text(x, bottom * 1.15, f"{m:.3g}", ha="center", va="bottom", rotation=90, fontsize=7,
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})
    ax.yaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.set_xticks(range(len(scenarios)))
    ax.set_xticklabels([f"{s}\n({SCENARIOS[s][0]} cameras {SCENARIOS[s][1]}x{SCENARIOS[s][2]} mono8)"
                        for s in scenarios])
    ax.set_ylabel("ms per sample (log scale): bar = median, whisker = p99")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=8, ncol=4, loc="upper left")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---- main ------------------------------------------------------------------------------------

def run_scenario(args, scenario: str, rng, out: str) -> tuple[dict, dict]:
    """Both phases of one scenario: (results by contender, facts about it)."""
    tcp_contenders, tcp_info, source = tcp_phase(args, scenario, rng, out)
    ipc_contenders, ipc_info = ipc_phase(args, scenario, rng, out, source)
    results = {c.name: result_of(c) for c in tcp_contenders + ipc_contenders}
    results[IMZ_PER_IMAGE] = per_image(results[IMZ], len(source[0]))
    results[IMZ_PER_IMAGE]["minor_faults_median"] = None
    return results, {"tcp": tcp_info, "ipc": ipc_info, "source_tuples": len(source)}


def report_errors(results: dict) -> None:
    for name, r in results.items():
        if r["failed"]:
            print(f"  {name}: {r['failed']} failed samples, first: {r['errors'][0][1]}")
            if r["summary_ms"]["n"] == 0 and r["first_traceback"]:
                print("    " + r["first_traceback"].rstrip().replace("\n", "\n    "))


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = common.parse_args(p, argv)
    if isinstance(args, int):
        return args
    out = common.ensure_dir(args.out)
    rng = random.Random(args.seed)
    started = time.time()
    host = common.host_info()
    print(common.code_line(common.code_version()))
    all_results, facts, broken = {}, {}, {}
    for scenario in args.scenarios:
        try:
            all_results[scenario], facts[scenario] = run_scenario(args, scenario, rng, out)
        except RuntimeError as exc:  # a service or child that did not start or stream
            broken[scenario] = common.describe_error(exc)
            print(f"compare: {scenario}: {broken[scenario]}", file=sys.stderr)
            continue
        print()
        print(scenario_table(scenario, all_results[scenario], SCENARIOS[scenario][0]))
        control = median(all_results[scenario], COPY_CONTROL)
        print(f"({IPC} ran on its own service after the others; the plain copy timed beside it: "
              f"median {common.fmt(control, 3)} ms, vs {common.fmt(median(all_results[scenario], COPY), 3)} "
              "ms in the main phase)")
        report_errors(all_results[scenario])
    tlist = targets(all_results)
    print()
    print_targets(tlist)
    empty = [f"{s}: {name}" for s, res in all_results.items() for name, r in res.items()
             if r["summary_ms"]["n"] == 0]
    for e in empty:
        print(f"every sample failed: {e}")

    json_path, png_path = os.path.join(out, "compare.json"), os.path.join(out, "compare.png")
    common.write_json(json_path, {
        "benchmark": "compare", "started_unix": started,
        "argv": sys.argv[1:] if argv is None else list(argv),
        "settings": dict(vars(args)), "seed": args.seed, "host": host,
        "clock": "samples are time.perf_counter_ns() around the timed call, in ms; None = failed",
        "scenarios": {s: {"cameras": SCENARIOS[s][0], "width": SCENARIOS[s][1], "height": SCENARIOS[s][2],
                          **facts[s], "contenders": all_results[s]} for s in all_results},
        "broken_scenarios": broken, "targets": tlist,
    })
    if all_results:
        plot(all_results, png_path, f"compare: median and p99 per contender, {args.samples} samples each, "
                                    f"seed {args.seed}")
        print(f"wrote {json_path} and {png_path}")
    else:
        print(f"wrote {json_path}")
    return common.EXIT_FAILED if broken or empty else common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
