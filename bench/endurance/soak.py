"""Soak: the service under steady load for --minutes; nothing may grow without bound.

Launches a service with 4 synthetic cameras (20 fps, 640x480 by default), 2 request/reply
clients (a tuple every 50 ms each), 2 live subscribers of the tuple stream and 1 stalled
subscriber (never reads). Every --every seconds it records, for every process of the
service (supervisor, coordinator, camera workers): resident memory (RSS) and open file
descriptors; plus the cameras' dropped frames and the request latency of the interval.
Prints the first and last samples side by side, and the growth; writes soak.json and
soak.png into --out.
"""

from __future__ import annotations

import os
import sys
import threading
import time

if not __package__:  # run as a script (python bench/endurance/soak.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common
from fxis_shm import FxisError, RequestTimeout
from fxis_shm.client.pubsub import Subscriber
from fxis_shm.service.launch import ServiceProcess


def service_processes(svc: ServiceProcess) -> dict[int, str]:
    """pid -> role of the supervisor and its children ("camera NAME", "coordinator", ...)."""
    return {svc.proc.pid: "supervisor", **{pid: key.replace(":", " ") for key, pid in svc.children().items()}}


def rss_kib(pid: int) -> int:
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def sample(svc: ServiceProcess) -> dict:
    out = {}
    for pid, role in service_processes(svc).items():
        try:
            out[role] = {"rss_kib": rss_kib(pid), "fds": len(os.listdir(f"/proc/{pid}/fd"))}
        except OSError:
            continue
    return out


def main(argv: list[str] | None = None) -> int:
    p = common.parser_for(__file__, __doc__)
    p.add_argument("--minutes", type=common.positive_float, default=10.0)
    p.add_argument("--every", type=common.positive_float, default=10.0, help="seconds between samples")
    common.add_frame_size_args(p, 640, 480)
    p.add_argument("--out", default=common.DEFAULT_OUT)
    args = p.parse_args(argv)
    out = common.ensure_dir(args.out)
    flags = common.synthetic_camera_flags([f"cam{i}" for i in range(4)], 20.0, args.width, args.height)
    stop = threading.Event()
    latencies: list[float] = []
    failures = [0]
    samples = []
    with open(os.path.join(out, "soak.service.log"), "wb") as log, ServiceProcess(flags, stderr=log) as svc:

        def requester():
            with svc.client(timeout=2.0) as client:
                while not stop.is_set():
                    t0 = time.monotonic_ns()
                    try:
                        client.tuple()
                        latencies.append(common.ms(time.monotonic_ns() - t0))
                    except FxisError:
                        failures[0] += 1
                    stop.wait(0.05)

        def subscriber():
            with Subscriber(svc.pub, timeout=0.5) as sub:
                sub.tuples()
                while not stop.is_set():
                    try:
                        sub.receive()
                    except RequestTimeout:
                        pass

        stalled = Subscriber(svc.pub, queue=2)
        stalled.tuples()
        threads = [threading.Thread(target=f) for f in (requester, requester, subscriber, subscriber)]
        for t in threads:
            t.start()
        try:
            with svc.client() as client:
                start = time.monotonic()
                bar = common.progress(int(args.minutes * 60 / args.every) + 1, "soak")
                while True:
                    status = client.status()
                    n = len(latencies)
                    samples.append(
                        {
                            "t_s": round(time.monotonic() - start, 1),
                            "processes": sample(svc),
                            "dropped": sum(c["frames_dropped"] for c in status["cameras"].values()),
                            "stored": sum(c["frames_stored"] for c in status["cameras"].values()),
                            "latency_ms": common.summary(latencies[-200:]) if n else None,
                            "requests": n,
                            "failures": failures[0],
                        }
                    )
                    bar.update()
                    if time.monotonic() - start >= args.minutes * 60:
                        break
                    time.sleep(args.every)
                bar.close()
        finally:
            stop.set()
            for t in threads:
                t.join(5)
            stalled.close()
    first, last = samples[0], samples[-1]
    rows = []
    for role in sorted(last["processes"]):
        a, b = first["processes"].get(role, {}), last["processes"][role]
        rows.append([role, a.get("rss_kib", 0) / 1024, b["rss_kib"] / 1024, a.get("fds", 0), b["fds"]])
    print(
        common.table(
            ["process", "RSS MiB start", "RSS MiB end", "fds start", "fds end"],
            rows,
            title=f"soak: {args.minutes:g} min, 4 cameras {args.width}x{args.height} at 20 fps, "
            f"2 clients, 3 subscribers (1 stalled); samples at {first['t_s']} s and {last['t_s']} s",
        )
    )
    lat = last["latency_ms"] or {}
    print(
        f"requests {last['requests']}, failed {last['failures']}; frames stored {last['stored']}, "
        f"dropped {last['dropped']}; tuple latency of the last 200: median {common.fmt(lat.get('median'))} ms, "
        f"p99 {common.fmt(lat.get('p99'))} ms"
    )
    common.write_json(os.path.join(out, "soak.json"), {"samples": samples, "code": common.code_version()})
    plt = common.pyplot()
    fig, ax = plt.subplots(figsize=(9, 4))
    for role in sorted(last["processes"]):
        ax.plot(
            [s["t_s"] for s in samples],
            [s["processes"].get(role, {}).get("rss_kib", 0) / 1024 for s in samples],
            label=role,
        )
    ax.set(xlabel="s", ylabel="RSS MiB", title="resident memory over the soak")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "soak.png"), dpi=100)
    return 1 if failures[0] else 0


if __name__ == "__main__":
    sys.exit(main())
