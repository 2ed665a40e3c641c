"""--fps-cameras 4 cameras 1360x1024 per --fps-steps frame rate (50 .. 300), a
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
"""

from __future__ import annotations

import os
import random
import threading
import time

from bench.scale import timing as shared
from bench.shared import common
from bench.shared.cpu import BENCH, HOST, IDLE, cpu_percent, cpu_sample, service_processes

FPS_EDGE_FRAMES = 2  # frames a step's window may miss at its edges
MIN_SERVED_SHARE = 0.9  # of --request-hz, for an fps step to pass
BUSY_HOST_PERCENT = 20.0  # CPU (% of a core) of other processes above which an fps step is flagged


# ---- one step ------------------------------------------------------------------------------


class PacedRequester(threading.Thread):
    """client.tuple() every 1/hz s on its own client (no bursts to catch up)."""

    def __init__(self, endpoint: str, timeout: float, path: str, hz: float):
        super().__init__(daemon=True)
        self.endpoint, self.timeout, self.path, self.period = endpoint, timeout, path, 1.0 / hz
        self.records: list[dict] = []
        self.stopping = threading.Event()

    def run(self) -> None:
        with shared.make_client(self.endpoint, self.timeout, self.path) as client:
            due = time.monotonic()
            while not self.stopping.is_set():
                self.records.append(shared.timed(client, shared.tuple_now))
                due += self.period
                delay = due - time.monotonic()
                if delay > 0:
                    self.stopping.wait(delay)
                else:
                    due = time.monotonic()

    def stop(self) -> None:
        self.stopping.set()
        self.join(self.timeout + 5)


def run(args, logs: shared.Logs, rng: random.Random) -> dict:
    steps = []
    with common.progress(len(args.fps_steps), "fps steps") as bar:
        bar.unit = "step"
        for fps in args.fps_steps:
            steps.append(measure_fps_step(args, logs, fps))
            bar.update(1)
    return {"steps": steps}


def measure_fps_step(args, logs: shared.Logs, fps: float) -> dict:
    run_args = shared.camera_args(args.fps_cameras, fps, 1360, 1024, args.slots)
    with logs.service("fps", run_args, args.timeout) as (svc, status), svc.client(timeout=args.timeout) as client:
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
    return fps_verdict(
        {
            "fps": fps,
            "processes": procs,
            "cpu_percent": cpu,
            "cpu_total": service,
            "cpu_others": cpu[HOST] - service - (cpu[BENCH] or 0.0),
            "cameras": frame_counts(s0, s1, fps),
            "seconds": (t1 - t0) / 1e9,
            "requests": shared.latency_summary(requests),
            "records": requests,
            "status_start": s0,
            "status_end": s1,
        },
        args.request_hz,
    )


def frame_counts(s0: dict, s1: dict, fps: float) -> dict:
    """Per camera: frames expected from the service clock, stored and dropped between two statuses."""
    expected = fps * (s1["now"] - s0["now"]) / 1e9
    out = {}
    for cam, c1 in s1["cameras"].items():
        c0 = s0["cameras"][cam]
        stored = c1["frames_stored"] - c0["frames_stored"]
        dropped = c1["frames_dropped"] - c0["frames_dropped"]
        out[cam] = {
            "expected": expected,
            "stored": stored,
            "dropped": dropped,
            "alive": c1["alive"] and c1["generation"] == c0["generation"],
            "lost": dropped > 0 or stored < expected - FPS_EDGE_FRAMES or not c1["alive"],
        }
    return out


def fps_verdict(step: dict, hz: float) -> dict:
    req = step["requests"]
    step["request_hz"] = hz
    step["served_per_s"] = (req["requests"] - req["failed"]) / step["seconds"]
    step["no_loss"] = not any(c["lost"] for c in step["cameras"].values())
    step["passed"] = step["no_loss"] and req["failed"] == 0 and step["served_per_s"] >= MIN_SERVED_SHARE * hz
    return step


def report(result: dict, args) -> None:
    rows = []
    for s in result["steps"]:
        cams = s["cameras"].values()
        expected = next(iter(cams))["expected"] if cams else None
        rows.append(
            [
                f"{s['fps']:g}",
                expected,
                ",".join(str(c["stored"]) for c in cams),
                ",".join(str(c["dropped"]) for c in cams),
                "yes" if s["no_loss"] else "NO",
                s["requests"]["requests"],
                s["requests"]["failed"],
                s["served_per_s"],
                s["requests"]["rtt_ms"]["median"],
                s["requests"]["rtt_ms"]["p99"],
                s["cpu_total"],
                "PASS" if s["passed"] else "FAIL",
            ]
        )
    print(
        common.table(
            [
                "fps",
                "expected",
                "stored per camera",
                "dropped per camera",
                "no loss",
                "requests",
                "failed",
                "req/s",
                "median ms",
                "p99 ms",
                "service CPU %",
                "step",
            ],
            rows,
            digits=1,
            title=f"fps: {args.fps_cameras} cameras 1360x1024, {args.seconds:g} s per step, "
            f"client.tuple() at {args.request_hz:g}/s ({args.load_path})",
        )
    )
    names = []
    for s in result["steps"]:
        names += [n for n in s["cpu_percent"] if n not in names]
    names = [n for n in names if n not in (BENCH, HOST)]
    rows = [
        [f"{s['fps']:g}"]
        + [s["cpu_percent"].get(n) for n in names]
        + [s["cpu_total"], s["cpu_percent"][BENCH], s["cpu_others"], s["cpu_percent"][HOST]]
        for s in result["steps"]
    ]
    print(
        common.table(
            ["fps"] + names + ["service", "bench", "others", "host"],
            rows,
            digits=1,
            separators=(len(names) + 1,),
            title=f"CPU % of one core per process over each step (out of {100 * (os.cpu_count() or 1)} % "
            "for all cores): service = its processes; bench = this client; others = the rest of "
            "the host (host busy - service - bench)",
        )
    )
    busy = [f"{s['fps']:g}" for s in result["steps"] if s["cpu_others"] > BUSY_HOST_PERCENT]
    if busy:
        print(
            f"note: other processes used more than {BUSY_HOST_PERCENT:g} % of a core during the steps at "
            f"{', '.join(busy)} fps: what they lost may be due to that load rather than to the service"
        )


def fps_target(result: dict, args) -> dict:
    """Judged on the step at --target-fps (or the next step above it); the failed steps are named."""
    steps = result["steps"]
    best = max((s["fps"] for s in steps if s["passed"]), default=None)
    judged = min((s for s in steps if s["fps"] >= args.target_fps), key=lambda s: s["fps"], default=None)
    failed = {f"{s['fps']:g}": step_trouble(s) for s in steps if not s["passed"]}
    return {
        "highest_passing_fps": best,
        "judged_fps": judged and judged["fps"],
        "passed": judged["passed"] if judged else None,
        "failed_steps": failed,
    }


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


def targets(result: dict, args) -> list[dict]:
    t = fps_target(result, args)
    return [
        {
            "target": f"{args.fps_cameras} cameras 1360x1024 at {args.target_fps:g} fps with no loss "
            f"while serving {args.request_hz:g} tuple req/s",
            "passed": t["passed"],
            "detail": fps_detail(t, args),
        }
    ]


def fps_detail(t: dict, args) -> str:
    best = t["highest_passing_fps"]
    text = (
        f"step {t['judged_fps']:g} fps {'passed' if t['passed'] else 'failed'}; "
        if t["judged_fps"]
        else f"no step at or above {args.target_fps:g} fps; "
    )
    text += f"highest step with no loss: {f'{best:g} fps' if best else 'none'}"
    if t["failed_steps"]:
        text += "; failed steps: " + "; ".join(f"{fps} fps ({why})" for fps, why in t["failed_steps"].items())
    return text


# ---- figures -------------------------------------------------------------------------------


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


PANELS = [plot_fps, plot_cpu]
