"""What the service's coordinator costs in CPU while it serves (issue 23, item 3): 4 cameras
1360x1024 at 100 fps with a network client asking 50 tuples per second; and one core's cost of
``latest()`` at 1 kHz from a client on the service's host (the local path, no coordinator).

One service is launched (--cameras synthetic mono8 cameras of --size at --fps, rings of --slots,
tcp loopback). Every round runs these phases in a random order, each for --seconds after
--settle-seconds, and the figures are the medians over --rounds rounds:

  idle         nobody asks: what following the cameras costs the coordinator by itself
  tuples       a client with local="off" calls client.tuple() (t* = the call, frames travel in the
               reply) every 1/--request-hz s, paced (no bursts to catch up)
  latest copy  a client with local="require" calls client.latest() every 1/--latest-hz s: the
               newest frame of every camera copied out of the rings by the client itself
  latest view  the same with copy=False (read-only views of the slots, no copy)

The calls are made by this process's main thread, whose CPU time (time.thread_time_ns) is the
client's cost: "% of one core" = CPU time / wall time. The coordinator's CPU is read per thread
from /proc/PID/task/TID/schedstat (ns on a CPU): its main thread (the poll loop, the engine, the
copies out of the rings, the replies), ZeroMQ's I/O thread (the TCP sends) and its other threads.
"per tuple" = (coordinator CPU in the tuples phase - in the idle phase) / replies. The camera
workers, the supervisor and the rest of the host are shown as a check of the load: on a machine
shared with other work every figure is noisy, hence the rounds and medians.

Writes coordinator_cpu.json (settings, seed, host, every phase of every round) into --out.
Exit status: 0 when every phase ran; 1 if the service did not start or a phase's every call
failed; 2 on bad flags.
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import sys
import time

if not __package__:  # run as a script (python bench/costs/coordinator.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.scale import timing as shared
from bench.shared import common
from bench.shared.cpu import HOST, IDLE, cpu_percent, cpu_sample, service_processes
from fxis_shm import Client

PHASES = ("idle", "tuples", "latest copy", "latest view")
COORDINATOR = "coordinator"
MAIN, IO, OTHER = "main thread", "ZeroMQ I/O", "other threads"


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    for flag, kind, default, text in (
        ("--cameras", common.positive_int, 4, "synthetic cameras"),
        ("--fps", common.positive_float, 100.0, "frame rate of every camera"),
        ("--slots", common.positive_int, 64, "frames per camera ring"),
        ("--request-hz", common.positive_float, 50.0, "tuple requests per second"),
        ("--latest-hz", common.positive_float, 1000.0, "latest() calls per second"),
        ("--seconds", common.positive_float, 5.0, "measured seconds per phase"),
        ("--settle-seconds", common.nonnegative_float, 1.0, "before each measurement"),
        ("--rounds", common.positive_int, 3, "rounds of every phase"),
    ):
        p.add_argument(flag, type=kind, default=default, help=text)
    p.add_argument("--size", type=shared.size_list, default=[(1360, 1024)], metavar="WxH", help="image size")
    p.add_argument(
        "--phases", type=common.name_list(PHASES), default=list(PHASES), help="comma-separated: " + ", ".join(PHASES)
    )
    common.add_output_args(p.add_argument_group("output"), seed_help="seed of the phases' order")
    return p


# ---- CPU of the coordinator's threads ----------------------------------------------------------


def thread_cpu_ns(pid: int) -> dict[str, int]:
    """ns on a CPU so far of the process's main thread, its ZeroMQ threads and the others."""
    out = {MAIN: 0, IO: 0, OTHER: 0}
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{tid}/schedstat") as f:
                ns = int(f.read().split()[0])
            with open(f"/proc/{pid}/task/{tid}/comm") as f:
                name = f.read().strip()
        except OSError:  # the thread ended meanwhile
            continue
        out[MAIN if int(tid) == pid else IO if name.startswith("ZMQbg") else OTHER] += ns
    return out


# ---- the callers -------------------------------------------------------------------------------


def paced(call, hz: float, seconds: float) -> dict:
    """``call()`` every 1/hz s for ``seconds`` (a late call is not caught up on): the calls made,
    the failed ones, the round trips and this thread's CPU time meanwhile."""
    period_ns, rtts, failed, first_error = int(1e9 / hz), [], 0, None
    cpu0 = time.thread_time_ns()
    start = due = time.monotonic_ns()
    end = start + int(seconds * 1e9)
    while True:
        now = time.monotonic_ns()
        if now >= end:
            break
        if due > now:
            time.sleep((due - now) / 1e9)
        t0 = time.monotonic_ns()
        try:
            result = call()
        except common.REQUEST_ERRORS as exc:
            failed += 1
            first_error = first_error or common.describe_error(exc)
        else:
            rtts.append(time.monotonic_ns() - t0)
            result.release()
        due = max(due + period_ns, time.monotonic_ns() - period_ns)
    wall = time.monotonic_ns() - start
    return {
        "calls": len(rtts) + failed,
        "failed": failed,
        "first_error": first_error,
        "rate_hz": (len(rtts) + failed) / wall * 1e9,
        "client_cpu_percent": (time.thread_time_ns() - cpu0) / wall * 100,
        "rtt_ms": common.summary(v / common.NS_PER_MS for v in rtts),
    }


def phase_call(name: str, clients: dict[str, Client]):
    if name == "tuples":
        return lambda: clients["network"].tuple()
    if name == "latest copy":
        return clients["local"].latest
    return lambda: clients["local"].latest(copy=False)


def run_phase(name: str, args, clients: dict[str, Client], procs: dict[str, int]) -> dict:
    hz = args.request_hz if name == "tuples" else args.latest_hz
    call = None if name == "idle" else phase_call(name, clients)
    if call is not None:
        paced(call, hz, args.settle_seconds)
    else:
        time.sleep(args.settle_seconds)
    coordinator = procs[COORDINATOR]
    threads0, cpu0, t0 = thread_cpu_ns(coordinator), cpu_sample(procs), time.monotonic_ns()
    if call is None:
        time.sleep(args.seconds)
        calls = {"calls": 0, "failed": 0, "rate_hz": 0.0, "client_cpu_percent": None, "rtt_ms": None}
    else:
        calls = paced(call, hz, args.seconds)
    wall = time.monotonic_ns() - t0
    threads1, cpu1 = thread_cpu_ns(coordinator), cpu_sample(procs)
    cpu = cpu_percent(cpu0, cpu1, wall / 1e9)
    cpu[HOST] = 100.0 * (os.cpu_count() or 1) - cpu.pop(IDLE)
    threads = {k: (threads1[k] - threads0[k]) / wall * 100 for k in threads0}
    return {
        "phase": name,
        **calls,
        "seconds": wall / 1e9,
        "coordinator_percent": sum(threads.values()),
        "coordinator_threads_percent": threads,
        "cameras_percent": sum(v or 0.0 for k, v in cpu.items() if k.startswith("camera:")),
        "cpu_percent": cpu,
    }


def run(args, rng: random.Random, logs) -> list[dict]:
    """Every phase --rounds times, in a random order each round, on one service."""
    w, h = args.size[0]
    run_args = shared.camera_args(args.cameras, args.fps, w, h, args.slots)
    results: list[dict] = []
    with (
        logs.service("coordinator_cpu", run_args, args.timeout) as (svc, status),
        Client(svc.endpoint, timeout=args.timeout, local="off") as network,
        Client(svc.endpoint, timeout=args.timeout, local="require") as local,
    ):
        procs = service_processes(status, svc.proc.pid)
        with common.progress(args.rounds * len(args.phases), "phases") as bar:
            for _ in range(args.rounds):
                for name in rng.sample(args.phases, len(args.phases)):
                    results.append(run_phase(name, args, {"network": network, "local": local}, procs))
                    bar.update(1)
    return results


# ---- report ------------------------------------------------------------------------------------


def med(phases: list[dict], key, sub: str | None = None) -> float | None:
    values = [p[key] if sub is None else p[key][sub] for p in phases]
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def summarize(results: list[dict]) -> dict:
    by_phase = {name: [r for r in results if r["phase"] == name] for name in PHASES}
    out = {}
    for name, phases in by_phase.items():
        if not phases:
            continue
        out[name] = {
            "rounds": len(phases),
            "rate_hz": med(phases, "rate_hz"),
            "failed": sum(p["failed"] for p in phases),
            "client_cpu_percent": med(phases, "client_cpu_percent"),
            "rtt_median_ms": med([p for p in phases if p["rtt_ms"]], "rtt_ms", "median"),
            "coordinator_percent": med(phases, "coordinator_percent"),
            **{t: med(phases, "coordinator_threads_percent", t) for t in (MAIN, IO, OTHER)},
            "cameras_percent": med(phases, "cameras_percent"),
            "host_percent": med(phases, "cpu_percent", HOST),
        }
    idle, tuples = out.get("idle"), out.get("tuples")
    if idle and tuples and tuples["rate_hz"]:
        extra = tuples["coordinator_percent"] - idle["coordinator_percent"]
        out["tuples"]["coordinator_ms_per_tuple"] = extra / 100 / tuples["rate_hz"] * 1e3
    return out


def report(summary: dict, args) -> str:
    w, h = args.size[0]
    rows = [
        [
            name,
            s["rate_hz"],
            s["failed"],
            s["rtt_median_ms"],
            s["client_cpu_percent"],
            s["coordinator_percent"],
            s[MAIN],
            s[IO],
            s[OTHER],
            s.get("coordinator_ms_per_tuple"),
            s["cameras_percent"],
            s["host_percent"],
        ]
        for name, s in summary.items()
    ]
    return common.table(
        ["phase", "calls/s", "failed", "rtt ms", "client %", "coordinator %", MAIN, IO, OTHER]
        + ["coord ms/tuple", "cameras %", "host %"],
        rows,
        digits=2,
        separators=(5, 10),
        title=f"{args.cameras} cameras {w}x{h} mono8 at {args.fps:g} fps; tuples at {args.request_hz:g}/s over tcp, "
        f"latest() at {args.latest_hz:g}/s local; CPU in % of one core, medians of {args.rounds} rounds of "
        f"{args.seconds:g} s",
    )


# ---- main --------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    args = common.parse_args(parser(), argv)
    if isinstance(args, int):  # --help, or bad flags
        return args
    host, out = common.host_info(), common.ensure_dir(args.out)
    print(common.code_line(host["code"]))
    try:
        results = run(args, random.Random(args.seed), shared.Logs(out))
    except RuntimeError as exc:  # the service did not start or stream
        print(f"coordinator_cpu: {common.describe_error(exc)}", file=sys.stderr)
        return common.EXIT_FAILED
    summary = summarize(results)
    print()
    print(report(summary, args))
    empty = [r["phase"] for r in results if r["calls"] and r["failed"] == r["calls"]]
    for name in dict.fromkeys(empty):
        print(f"every call failed in a {name} phase: {next(r['first_error'] for r in results if r['phase'] == name)}")
    path = os.path.join(out, "coordinator_cpu.json")
    common.write_json(
        path,
        {
            "benchmark": "coordinator_cpu",
            "argv": sys.argv[1:] if argv is None else list(argv),
            "settings": dict(vars(args)),
            "seed": args.seed,
            "host": host,
            "log": os.path.join(out, "scaling.coordinator_cpu.service.log"),
            "summary": summary,
            "phases": results,
        },
    )
    print(f"wrote {path}")
    return common.EXIT_FAILED if empty else common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
