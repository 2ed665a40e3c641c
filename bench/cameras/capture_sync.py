"""Capture at T and lockstep on emulated hosts: the residual |t_capture - T| per camera, and the
joint skew of lockstep cameras beside the same services' free-running ones.

Makes --hosts emulated hosts (tests/hosts.py: namespaces, CLOCK_MONOTONIC 1000 s, 2000 s, ...
ahead, CurveZMQ; needs root), each a service with two software-triggered synthetic cameras
(trigger_latency_ms=3: the worker learns it). Part 1 (capture at T): --requests tuples
``Client(all).tuple(at=now + --lead-ms, capture=True)``, each camera's true capture time (its
service's stamp less its host's offset, exact) minus T. Part 2 (lockstep): the services again
with ``--lockstep --hz`` and one free-running camera more each (at --hz, started apart), then
--tuples joint tuples of the lockstep cameras and of the free ones at the same t*, the true
skew (max - min) of each. It prints the distributions (ms), the workers' timer lateness and
learned latency, and the machine's load: the figures are the timers' on a shared machine.

    sudo .venv/bin/python bench/cameras/capture_sync.py --hosts 3 --requests 200 --tuples 1000
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

if not __package__:  # run as a script: the project root on the path (tests.hosts)
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))

from fxis_shm import Client  # noqa: E402
from fxis_shm.errors import ServiceError  # noqa: E402
from tests.hosts import HostsUnavailable, Lab  # noqa: E402

SMALL = "width=64,height=48"
TRIGGERED = f"synthetic:trigger=software,trigger_latency_ms=3,{SMALL}"
PERCENTILES = (50, 90, 99, 100)


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


def capture_at(lab: Lab, hosts, args) -> tuple[dict[str, list[int]], list[str]]:
    services = [host.service(*_cameras(k, free=False)) for k, host in enumerate(hosts)]
    offsets = {f"h{k}{c}": host.clock_offset_ns for k, host in enumerate(hosts) for c in "ab"}
    residuals: dict[str, list[int]] = {name: [] for name in offsets}
    refused: list[str] = []  # T passed before the command reached a worker: the machine's load
    with _client(lab, services) as client:
        for i in range(args.requests + 3):  # the first 3: the workers learn their latency
            at = time.monotonic_ns() + int(args.lead_ms * 1e6)
            try:
                tup = client.tuple(at=at, capture=True)
            except ServiceError as exc:
                refused.append(exc.message)
                continue
            if i >= 3:
                for name, frame in tup.items():
                    residuals[name].append(frame.service_t_capture - offsets[name] - at)
        _print_sync(client, list(offsets))
    for svc in services:
        svc.stop()
    return residuals, refused


def lockstep(lab: Lab, hosts, args) -> tuple[list[int], list[int]]:
    services = []
    for k, host in enumerate(hosts):
        services.append(host.service("--lockstep", str(args.hz), *_cameras(k, free=True, hz=args.hz)))
        time.sleep(0.011)  # started apart: the free cameras' phases differ
    offsets = {f"h{k}{c}": host.clock_offset_ns for k, host in enumerate(hosts) for c in "abf"}
    triggered = [n for n in offsets if not n.endswith("f")]
    free = [n for n in offsets if n.endswith("f")]
    skews: tuple[list[int], list[int]] = ([], [])
    with _client(lab, services) as client:
        time.sleep(1.0)
        for _ in range(args.tuples):
            at = time.monotonic_ns() - 200_000_000  # stored frames
            for names, out in ((triggered, skews[0]), (free, skews[1])):
                true = [f.service_t_capture - offsets[n] for n, f in client.tuple(names, at=at).items()]
                out.append(max(true) - min(true))
            time.sleep(1 / args.hz)
        _print_sync(client, triggered)
    for svc in services:
        svc.stop()
    return skews


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


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--hosts", type=int, default=3, help="emulated hosts (default 3)")
    p.add_argument("--requests", type=int, default=200, help="capture-at-T requests (default 200)")
    p.add_argument("--lead-ms", type=float, default=100.0, help="T = now + this (default 100)")
    p.add_argument("--tuples", type=int, default=1000, help="lockstep tuples (default 1000)")
    p.add_argument("--hz", type=float, default=20.0, help="lockstep rate (default 20)")
    args = p.parse_args(argv)
    if args.hosts < 1 or args.requests < 1 or args.tuples < 1 or args.hz <= 0:
        p.error("--hosts, --requests, --tuples and --hz must be positive")
    load = os.getloadavg()
    try:
        with Lab() as lab:
            hosts = [lab.host(clock_offset_s=1000 * (k + 1)) for k in range(args.hosts)]
            print(f"capture at T = now + {args.lead_ms:g} ms, {args.requests} requests, {args.hosts} hosts:")
            residuals, refused = capture_at(lab, hosts, args)
            if refused:
                print(f"{len(refused)} requests refused, e.g.: {refused[0]}")
            for name, values in residuals.items():
                print(distribution(f"|t_capture - T| {name}", values))
            print(distribution("|t_capture - T| all cameras", [v for vs in residuals.values() for v in vs]))
            print(f"lockstep at {args.hz:g} Hz, {args.tuples} tuples of {2 * args.hosts} cameras:")
            stepped, free = lockstep(lab, hosts, args)
            print(distribution("skew, lockstep cameras", stepped))
            print(distribution(f"skew, free cameras ({args.hosts})", free))
    except HostsUnavailable as exc:
        print(f"cannot make emulated hosts: {exc}", file=sys.stderr)
        return 2
    print(f"{os.cpu_count()} CPUs, load average {load[0]:.2f} before, {os.getloadavg()[0]:.2f} after")
    return 0


if __name__ == "__main__":
    sys.exit(main())
