"""What the ring's ordered accesses cost: per stored frame (writer) and per read (reader).

Runs the same measurement twice in fresh processes, once with the fences of the
fxis_shm.shm._ordered helper (what the service uses) and once with plain accesses
(FXIS_PLAIN_ORDERING=1: correct on x86-64 only), on a real shared-memory ring of
--slots slots of --width x --height mono8 frames:

  write      RingWriter.write of one frame (the seqlock stores, the copy, the timing update)
  snapshot   RingReader.snapshot (write counter loads, table copy, validity)
  copy       RingReader.copy of the newest frame into a reused buffer (seq checks + copy)
  load       one ordered load of the write counter (RingReader.field("write_count"))

Prints the median of --repeat rounds of --n operations each, in microseconds, and the
difference the fences make. Exit status 0, or 2 on bad flags.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

if not __package__:  # run as a script (python bench/costs/ring_ordering.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    p.add_argument("-n", type=common.positive_int, default=2000, help="operations per round")
    p.add_argument("--repeat", type=common.positive_int, default=7, help="rounds; the median is reported")
    common.add_frame_size_args(p, 640, 480)
    p.add_argument("--slots", type=common.positive_int, default=16)
    p.add_argument("--measure", action="store_true", help=argparse.SUPPRESS)  # the child's part
    return p


def measure(args) -> dict:
    """Microseconds per operation in this process's ordering mode."""
    import numpy as np

    from fxis_shm.shm import ordering
    from fxis_shm.shm.naming import remove_leftovers
    from fxis_shm.shm.ring import FrameLayout, RingReader, RingWriter

    service = f"ro{os.getpid()}"
    layout = FrameLayout(args.height, args.width)
    image = np.zeros(layout.shape, np.uint8)
    writer = RingWriter(service, "cam", layout, args.slots, nominal_period_ns=10_000_000)
    reader = RingReader(service, "cam", with_semaphore=False)
    out = np.empty(layout.shape, np.uint8)
    frame = [0]

    def write():
        frame[0] += 1
        writer.write(image, frame[0], time.monotonic_ns())

    def copy():
        snap = reader.snapshot()
        reader.copy(snap, len(snap.timeline) - 1, out)

    ops = {"write": write, "snapshot": reader.snapshot, "copy": copy, "load": lambda: reader.field("write_count")}
    result = {"mode": ordering.MODE}
    try:
        for _ in range(args.slots):
            write()
        for name, op in ops.items():
            rounds = []
            for _ in range(args.repeat):
                t0 = time.perf_counter_ns()
                for _ in range(args.n):
                    op()
                rounds.append((time.perf_counter_ns() - t0) / args.n / 1e3)
            result[name] = statistics.median(rounds)
    finally:
        reader.close()
        writer.close()
        remove_leftovers(service)
    return result


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = common.parse_args(p, argv)
    if isinstance(args, int):
        return args
    if args.measure:
        print(json.dumps(measure(args)))
        return common.EXIT_OK
    child = [
        sys.executable,
        os.path.abspath(__file__),
        "--measure",
        "-n",
        str(args.n),
        "--repeat",
        str(args.repeat),
        "--width",
        str(args.width),
        "--height",
        str(args.height),
        "--slots",
        str(args.slots),
    ]
    runs = {}
    for label, plain in (("fenced", "0"), ("plain", "1")):
        env = {**os.environ, "FXIS_PLAIN_ORDERING": plain}
        done = subprocess.run(child, env=env, capture_output=True, text=True, check=True)
        runs[label] = json.loads(done.stdout)
    rows = [
        [op, f"{runs['plain'][op]:.2f}", f"{runs['fenced'][op]:.2f}", f"{runs['fenced'][op] - runs['plain'][op]:+.2f}"]
        for op in ("write", "snapshot", "copy", "load")
    ]
    print(
        f"ring_ordering: {common.code_line(common.code_version())}; {args.width}x{args.height} mono8, "
        f"{args.slots} slots; modes {runs['plain']['mode']} vs {runs['fenced']['mode']}"
    )
    print(
        common.table(
            ["us per op", "plain", "fenced", "fences cost"], rows, title=f"median of {args.repeat} rounds of {args.n}"
        )
    )
    return common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
