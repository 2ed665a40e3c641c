"""2 cameras 1360x1024 at --clients-fps 20 fps, one service for the section:
(a) --idle-counts extra connected clients (each did one status()) that then stay
idle, while one client times -n past tuples: the latency should stay flat;
(b) --active-counts clients that each ask past tuples back to back for
--active-seconds, spread over up to --processes worker processes (threads in
each, one Client per thread). Per count: median and p99 latency over every request,
requests/s, frames/s and MB/s in total.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import random
import threading
import time

from bench.scale import timing as shared
from bench.shared import common

IDLE_MARGIN = 1.25  # median with the most idle clients / median with none
WORKER_WAIT_S = 60.0  # longest a worker process of the active clients waits for its peers


# ---- (b) the active clients' worker processes ------------------------------------------------


def active_worker(conn) -> None:
    """Worker process of the active clients: on each task, ``threads`` clients connect, wait
    for the common start, ask past tuples back to back until the end, and report every request."""
    conn.send("up")
    while True:
        task = conn.recv()
        if task is None:
            return
        records: list[list[dict]] = [[] for _ in range(task["threads"])]
        ready = threading.Barrier(task["threads"] + 1)
        window = {}
        go = threading.Event()

        def client_thread(j: int, task=task, records=records, ready=ready, go=go, window=window) -> None:
            with shared.make_client(task["endpoint"], task["timeout"], task["path"]) as client:
                try:
                    client.status()
                except common.REQUEST_ERRORS as exc:
                    records[j].append(
                        {"t_send": time.monotonic_ns(), "rtt_ns": 0, "error": "connect: " + common.describe_error(exc)}
                    )
                ready.wait(WORKER_WAIT_S)
                if go.wait(WORKER_WAIT_S):
                    time.sleep(max(0, window["start"] - time.monotonic_ns()) / 1e9)  # the common start
                    while time.monotonic_ns() < window["end"]:
                        records[j].append(shared.timed(client))

        threads = [threading.Thread(target=client_thread, args=(j,), daemon=True) for j in range(task["threads"])]
        for t in threads:
            t.start()
        ready.wait(WORKER_WAIT_S)
        conn.send("ready")
        window["start"], window["end"] = conn.recv()
        go.set()
        for t in threads:
            t.join()
        conn.send([r for rs in records for r in rs])


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
        used = self.workers[: min(clients, len(self.workers))]
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


# ---- the section -----------------------------------------------------------------------------


def run(args, logs: shared.Logs, rng: random.Random) -> dict:
    run_args = shared.camera_args(2, args.clients_fps, 1360, 1024, args.slots)
    with (
        ActiveClients(min(args.processes, max(args.active_counts)), args.timeout) as pool,
        logs.service("clients", run_args, args.timeout) as (svc, status),
    ):
        idle = measure_idle(args, svc.endpoint, rng)
        active = [measure_active(args, pool, svc.endpoint, n) for n in args.active_counts]
    return {"status": status, "idle": idle, "active": active}


def measure_idle(args, endpoint: str, rng: random.Random) -> list[dict]:
    points, idle = [], []
    try:
        with shared.make_client(endpoint, args.timeout, args.load_path) as client:
            for count in sorted(args.idle_counts):
                while len(idle) < count:
                    extra = shared.make_client(endpoint, args.timeout, args.load_path)
                    idle.append(extra)
                    extra.status()  # really connected; from now on it stays idle
                records = shared.time_requests(
                    client, args.requests, rng, args.sleep_max_ms, args.warmup, f"idle clients {count}"
                )
                points.append({"idle": count, "summary": shared.latency_summary(records), "records": records})
    finally:
        for extra in idle:
            extra.close()
    return points


def measure_active(args, pool: ActiveClients, endpoint: str, clients: int) -> dict:
    records, start, end = pool.run(endpoint, clients, args.active_seconds, args.load_path)
    ok = [r for r in records if r["error"] is None]
    seconds = (max([r["t_send"] + r["rtt_ns"] for r in ok], default=end) - start) / 1e9
    summary = shared.latency_summary(records)
    return {
        "clients": clients,
        "seconds": seconds,
        "summary": summary,
        "requests_per_s": len(ok) / seconds,
        "frames_per_s": sum(r["frames"] for r in ok) / seconds,
        "mb_per_s": sum(r["bytes"] for r in ok) / shared.MB / seconds,
        "rtt_ms": [round(common.ms(r["rtt_ns"]), 3) for r in ok],
    }


def idle_flatness(idle: list[dict]) -> dict:
    meds = {p["idle"]: p["summary"]["rtt_ms"]["median"] for p in idle}
    if 0 not in meds or len(meds) < 2 or not meds[0]:
        return {"passed": None, "why": "needs 0 idle clients and another count"}
    most = max(meds)
    ratio = meds[most] / meds[0]
    return {
        "most": most,
        "median_ms": meds[most],
        "median_none_ms": meds[0],
        "ratio": ratio,
        "passed": ratio <= IDLE_MARGIN,
    }


def report(result: dict, args) -> None:
    rows = [
        [
            f"{p['idle']} idle",
            p["summary"]["requests"],
            p["summary"]["failed"],
            p["summary"]["rtt_ms"]["median"],
            p["summary"]["rtt_ms"]["p99"],
            p["summary"]["service_ms"]["median"],
        ]
        for p in result["idle"]
    ]
    print(
        common.table(
            ["clients", "n", "failed", "median ms", "p99 ms", "service ms"],
            rows,
            digits=2,
            title="clients (a): one client times past tuples while others stay idle (2 cameras 1360x1024)",
        )
    )
    rows = [
        [
            f"{p['clients']} active",
            p["summary"]["requests"],
            p["summary"]["failed"],
            p["summary"]["rtt_ms"]["median"],
            p["summary"]["rtt_ms"]["p99"],
            p["summary"]["service_ms"]["median"],
            p["requests_per_s"],
            p["frames_per_s"],
            p["mb_per_s"],
        ]
        for p in result["active"]
    ]
    print(
        common.table(
            ["clients", "requests", "failed", "median ms", "p99 ms", "service ms", "req/s", "frames/s", "MB/s"],
            rows,
            digits=1,
            title="clients (b): every client asks past tuples back to back",
        )
    )


def targets(result: dict, args) -> list[dict]:
    f = idle_flatness(result["idle"])
    detail = (
        f"median {f['median_ms']:.2f} ms with {f['most']} idle clients vs {f['median_none_ms']:.2f} ms "
        f"with none: {f['ratio']:.2f}x (limit {IDLE_MARGIN:g}x)"
        if "ratio" in f
        else f["why"]
    )
    return [{"target": f"flat with idle clients ({args.load_path})", "passed": f["passed"], "detail": detail}]


def plot_latency(ax, points: list[dict], x: list, what: str = "") -> None:
    """Median and p99 round trip of every point over ``x``."""
    ax.plot(x, [p["summary"]["rtt_ms"]["median"] for p in points], "o-", label="median" + what)
    ax.plot(x, [p["summary"]["rtt_ms"]["p99"] for p in points], "^:", label="p99" + what)


def plot_idle(ax, results, args) -> None:
    idle = results["clients"]["idle"]
    x = [p["idle"] for p in idle]
    plot_latency(ax, idle, x)
    ax.set_xscale("symlog", linthresh=1)
    ax.set_xticks(x)
    shared.plain_numbers(ax.xaxis)
    ax.set_ylim(bottom=0)
    ax.set_xlabel("idle connected clients")
    ax.set_ylabel("past tuple round trip, ms")
    ax.set_title(f"clients (a): idle clients ({args.load_path})")
    ax.legend(fontsize=7)


def plot_active(ax, results, args) -> None:
    active = results["clients"]["active"]
    x = [p["clients"] for p in active]
    plot_latency(ax, active, x, " latency")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xticks(x)
    shared.plain_numbers(ax.xaxis, ax.yaxis)
    ax.set_xlabel("active clients (back to back)")
    ax.set_ylabel("past tuple round trip, ms (log)")
    ax.legend(fontsize=7, loc="upper left")
    twin = ax.twinx()
    twin.plot(x, [p["requests_per_s"] for p in active], "s--", color="tab:green", label="requests/s")
    twin.set_ylabel("requests/s, all clients", color="tab:green")
    twin.set_ylim(bottom=0)
    twin.legend(fontsize=7, loc="lower right")
    ax.set_title(f"clients (b): active clients ({args.load_path})")


PANELS = [plot_idle, plot_active]
