"""What a service's start and stop cost in CPU, with its workers forked from the supervisor (the
default) and with each in a fresh interpreter (FXIS_SPAWN=exec), and how long the start takes.

Each round, in a random order of the two ways, launches ``fxis run`` with --cameras small
synthetic cameras (64x48 at 50 fps), waits until it answers ``status``, stops it and waits for it
to exit: its CPU (with every child's, reaped) is this process's RUSAGE_CHILDREN before and after.
Prints the medians over --rounds rounds; writes startup.json (every round) into --out.
Exit status 0; 1 if a service did not start; 2 on bad flags.
"""

from __future__ import annotations

import os
import random
import resource
import statistics
import subprocess
import sys
import time

if not __package__:  # run as a script (python bench/costs/startup.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common
from fxis_shm import FxisError
from fxis_shm.service.launch import ServiceProcess

WAYS = ("fork", "exec")  # FXIS_SPAWN


def children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def one_start(way: str, cameras: int) -> dict:
    args = [arg for k in range(cameras) for arg in ("--camera", f"cam{k}=synthetic:fps=50,width=64,height=48")]
    svc = ServiceProcess(args, stderr=subprocess.DEVNULL, env={**os.environ, "FXIS_SPAWN": way})
    cpu, wall = children_cpu_s(), time.monotonic()
    svc.start()
    started = time.monotonic() - wall
    svc.stop()
    return {"way": way, "start_s": started, "cpu_s": children_cpu_s() - cpu}


def main(argv: list[str] | None = None) -> int:
    p = common.parser_for(__file__, __doc__)
    p.add_argument("--rounds", type=int, default=10, help="starts of each way (default: 10)")
    p.add_argument("--cameras", type=int, default=2, help="cameras per service (default: 2)")
    p.add_argument("--seed", type=int, default=None, help="seed of the order of the ways (default: random)")
    p.add_argument("--out", default=common.DEFAULT_OUT)
    args = p.parse_args(argv)
    if args.rounds < 1 or args.cameras < 1:
        p.error("--rounds and --cameras must be at least 1")
    rng = random.Random(args.seed)
    runs = []
    try:
        for _ in range(args.rounds):
            for way in rng.sample(WAYS, len(WAYS)):
                runs.append(one_start(way, args.cameras))
    except FxisError as exc:
        print(f"startup: a service did not start: {exc}", file=sys.stderr)
        return 1
    print(f"a service of {args.cameras} cameras, started and stopped {args.rounds} times each way (medians)")
    for way in WAYS:
        mine = [run for run in runs if run["way"] == way]
        cpu = statistics.median(run["cpu_s"] for run in mine)
        start = statistics.median(run["start_s"] for run in mine)
        print(f"  {way:<5} {cpu:6.2f} CPU-s   start {start * 1e3:6.0f} ms")
    out = common.ensure_dir(args.out)
    common.write_json(os.path.join(out, "startup.json"), {"seed": args.seed, "cameras": args.cameras, "runs": runs})
    return 0


if __name__ == "__main__":
    sys.exit(main())
