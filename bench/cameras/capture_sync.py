"""Capture at T and lockstep on emulated hosts, under three conditions side by side: no load,
--load busy loops, and the same load with the services under ``fxis run --realtime``.

Makes --hosts emulated hosts (tests/hosts.py: namespaces, CLOCK_MONOTONIC 1000 s, 2000 s, ...
ahead, CurveZMQ; needs root), each a service with two software-triggered synthetic cameras
(trigger_latency_ms=3: the worker learns it). Per condition: part 1 (capture at T), --requests
tuples ``Client(all).tuple(at=now + --lead-ms, capture=True)``, each camera's true capture time
(its service's stamp less its host's offset, exact) minus T; part 2 (lockstep), the services
again with ``--lockstep --hz`` and one free-running camera more each (at --hz, started apart),
then --tuples joint tuples of the lockstep cameras and of the free ones at the same t*, the true
skew (max - min) of each, and the grid points the timers gave up. The busy loops (``while True:
pass`` processes at normal priority) are the bench's own, started before and ended after their
conditions. It prints each condition's figures (ms), the workers' timer lateness and learned
latency, under --realtime the CPU each lockstep camera's timer thread took, then the table.

    sudo .venv/bin/python bench/cameras/capture_sync.py --hosts 2 --load 4 --requests 200 --tuples 400
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field

import numpy as np

if not __package__:  # run as a script: the project root on the path (tests.hosts)
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))

from fxis_shm import Client  # noqa: E402
from fxis_shm.errors import ServiceError  # noqa: E402
from fxis_shm.service import realtime  # noqa: E402
from fxis_shm.service.rtpolicy import DEFAULT_PRIORITY  # noqa: E402
from tests.hosts import HostsUnavailable, Lab  # noqa: E402

SMALL = "width=64,height=48"
TRIGGERED = f"synthetic:trigger=software,trigger_latency_ms=3,{SMALL}"
PERCENTILES = (50, 90, 99, 100)
BUSY_LOOP = "while True: pass"


@dataclass
class Condition:
    name: str
    load: int  # busy loops beside the services
    service_args: tuple[str, ...] = ()
    residuals: list[int] = field(default_factory=list)  # |t_capture - T|, every camera
    skews: list[int] = field(default_factory=list)  # lockstep cameras' joint skew
    missed: int = 0  # lockstep grid points given up while the tuples were taken, all cameras
    refused: int = 0  # capture requests whose T passed before the command reached a worker


def distribution(label: str, values_ns) -> str:
    a = np.abs(np.asarray(values_ns, dtype=float)) / 1e6
    cells = "  ".join(f"p{p}={np.percentile(a, p):7.3f}" for p in PERCENTILES)
    return f"{label:<34} n={a.size:<5} {cells}   (ms)"


def _client(lab: Lab, services) -> Client:
    client = Client([s.endpoint for s in services], timeout=15, keys=lab.client_keys)
    deadline = time.monotonic() + 60
    while not all((e := client.clocks.get(s.endpoint)) and e.method == "estimated" for s in services):
        if time.monotonic() > deadline:
            raise TimeoutError("no clock estimates within 60 s")
        time.sleep(0.1)
    return client


def capture_at(lab: Lab, hosts, args, cond: Condition) -> None:
    services = [host.service(*cond.service_args, *_cameras(k, free=False)) for k, host in enumerate(hosts)]
    offsets = {f"h{k}{c}": host.clock_offset_ns for k, host in enumerate(hosts) for c in "ab"}
    residuals: dict[str, list[int]] = {name: [] for name in offsets}
    with _client(lab, services) as client:
        for i in range(args.requests + 3):  # the first 3: the workers learn their latency
            at = time.monotonic_ns() + int(args.lead_ms * 1e6)
            try:
                tup = client.tuple(at=at, capture=True)
            except ServiceError:
                cond.refused += 1
                continue
            if i >= 3:
                for name, frame in tup.items():
                    residuals[name].append(frame.service_t_capture - offsets[name] - at)
        _print_sync(client, list(offsets))
    for svc in services:
        svc.stop()
    for name, values in residuals.items():
        print(distribution(f"|t_capture - T| {name}", values))
    cond.residuals = [v for vs in residuals.values() for v in vs]


def lockstep(lab: Lab, hosts, args, cond: Condition) -> None:
    services = []
    for k, host in enumerate(hosts):
        services.append(
            host.service(*cond.service_args, "--lockstep", str(args.hz), *_cameras(k, free=True, hz=args.hz))
        )
        time.sleep(0.011)  # started apart: the free cameras' phases differ
    offsets = {f"h{k}{c}": host.clock_offset_ns for k, host in enumerate(hosts) for c in "abf"}
    triggered = [n for n in offsets if not n.endswith("f")]
    free = [n for n in offsets if n.endswith("f")]
    skews: tuple[list[int], list[int]] = ([], [])
    with _client(lab, services) as client:
        time.sleep(1.0)
        timers = _timer_threads(client, triggered)
        missed_before = _missed(client.status(), triggered)  # the measurement's own, not the start-up's
        cpu_before, t_before = {n: _cpu_ns(*t) for n, t in timers.items()}, time.monotonic_ns()
        for _ in range(args.tuples):
            at = time.monotonic_ns() - 200_000_000  # stored frames
            for names, out in ((triggered, skews[0]), (free, skews[1])):
                true = [f.service_t_capture - offsets[n] for n, f in client.tuple(names, at=at).items()]
                out.append(max(true) - min(true))
            time.sleep(1 / args.hz)
        elapsed = time.monotonic_ns() - t_before
        _print_sync(client, triggered)
        cond.missed = _missed(client.status(), triggered) - missed_before
        for name, thread in timers.items():  # the timer at FIFO: what its 2 ms of spinning cost
            share = (_cpu_ns(*thread) - cpu_before[name]) / elapsed
            at_fifo = f"timer thread at SCHED_FIFO {DEFAULT_PRIORITY}"
            print(f"  {name}: {at_fifo}: {100 * share:.2f} % of a core at {args.hz:g} Hz")
    for svc in services:
        svc.stop()
    print(distribution("skew, lockstep cameras", skews[0]))
    print(distribution(f"skew, free cameras ({len(hosts)})", skews[1]))
    cond.skews = skews[0]


def _missed(status: dict, names: list[str]) -> int:
    return sum(status["cameras"][name]["sync"]["triggers_missed"] for name in names)


def _timer_threads(client: Client, names: list[str]) -> dict[str, tuple[int, int]]:
    """Each camera's (pid, tid) of its trigger timer: the one thread at the timers' FIFO priority
    (none without --realtime)."""
    services = client.status()["services"].values()
    processes = {k: v for s in services for k, v in ((s.get("supervisor") or {}).get("processes") or {}).items()}
    found = {}
    for name in names:
        pid = processes[f"camera:{name}"]["pid"]
        tids = [tid for tid, p in realtime.threads_of(pid).items() if p == (1, DEFAULT_PRIORITY)]
        if len(tids) == 1:
            found[name] = (pid, tids[0])
    return found


def _cpu_ns(pid: int, tid: int) -> int:
    with open(f"/proc/{pid}/task/{tid}/schedstat") as f:  # time on a CPU, ns
        return int(f.read().split()[0])


def _cameras(k: int, free: bool, hz: float = 20) -> list[str]:
    flags = ["--camera", f"h{k}a={TRIGGERED}", "--camera", f"h{k}b={TRIGGERED}"]
    return [*flags, "--camera", f"h{k}f=synthetic:fps={hz},{SMALL}"] if free else flags


def _print_sync(client: Client, names: list[str]) -> None:
    cameras = client.status()["cameras"]
    for name in names:
        s = cameras[name]["sync"]
        grid = s["lockstep"]
        print(
            f"  {name}: latency {s['trigger_latency_ms']:.3f} ms learned, timer late p50 {s['timer_late_p50_ms']:.3f}"
            f" p99 {s['timer_late_p99_ms']:.3f} ms, missed {s['triggers_missed']}"
            + (
                f", grid residual p50 {grid['residual_p50_ms']:.3f} p99 {grid['residual_p99_ms']:.3f} ms"
                if grid
                else ""
            )
        )


def busy_loops(count: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", BUSY_LOOP]) for _ in range(count)]


def _figures(values_ns: list[int]) -> str:
    if not values_ns:
        return "-"
    a = np.abs(np.asarray(values_ns, dtype=float)) / 1e6
    return " / ".join(f"{np.percentile(a, p):.2f}" for p in (50, 99, 100))


def table(conditions: list[Condition]) -> list[str]:
    rows = [("condition", "|t_capture - T| p50/p99/max", "lockstep skew p50/p99/max", "grid points missed", "refused")]
    rows += [(c.name, _figures(c.residuals), _figures(c.skews), str(c.missed), str(c.refused)) for c in conditions]
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--hosts", type=int, default=2, help="emulated hosts (default 2)")
    p.add_argument("--load", type=int, default=4, help="busy loops of the loaded conditions (default 4)")
    p.add_argument("--requests", type=int, default=200, help="capture-at-T requests per condition (default 200)")
    p.add_argument("--lead-ms", type=float, default=100.0, help="T = now + this (default 100)")
    p.add_argument("--tuples", type=int, default=400, help="lockstep tuples per condition (default 400)")
    p.add_argument("--hz", type=float, default=20.0, help="lockstep rate (default 20)")
    p.add_argument("--logs", metavar="DIR", help="keep the services' logs here (default: removed with the hosts)")
    args = p.parse_args(argv)
    if args.hosts < 1 or args.requests < 1 or args.tuples < 1 or args.hz <= 0 or args.load < 0:
        p.error("--hosts, --requests, --tuples and --hz must be positive, --load at least 0")
    conditions = [
        Condition("no load", 0),
        Condition(f"{args.load} busy loops", args.load),
        Condition(f"{args.load} busy loops, --realtime", args.load, ("--realtime",)),
    ]
    load = os.getloadavg()
    try:
        with Lab(log_dir=args.logs) as lab:
            hosts = [lab.host(clock_offset_s=1000 * (k + 1)) for k in range(args.hosts)]
            for cond in conditions:
                loops = busy_loops(cond.load)
                try:
                    print(f"== {cond.name}: capture at T = now + {args.lead_ms:g} ms, {args.requests} requests, "
                          f"{args.hosts} hosts")  # fmt: skip
                    capture_at(lab, hosts, args, cond)
                    print(
                        f"== {cond.name}: lockstep at {args.hz:g} Hz, {args.tuples} tuples of {2 * args.hosts} cameras"
                    )
                    lockstep(lab, hosts, args, cond)
                finally:
                    for loop in loops:
                        loop.kill()
                        loop.wait()
    except HostsUnavailable as exc:
        print(f"cannot make emulated hosts: {exc}", file=sys.stderr)
        return 2
    print("\n".join(table(conditions)))
    print(f"(ms; {os.cpu_count()} CPUs, load average {load[0]:.2f} before, {os.getloadavg()[0]:.2f} after)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
