"""A processing hook slower than the frame period, spread over processes: are the frames stored
in order, and how many does this machine drop?

For each count of --workers (default 1 and 3) a service is launched with one synthetic mono8
camera (--fps, default 20; 64x48, so that rendering costs nothing) whose every frame first goes
through a hook of known cost, process=slow_hooks:sleep_60ms (60 ms of sleep: more than the
50 ms between frames at 20 fps; bench/cameras/slow_hooks.py, bench/ is put on the camera workers'
PYTHONPATH), process_workers=N. After --warmup seconds the camera's counters are read, then
again after --seconds, and every frame captured in between is fetched with one "range"
sequence (the ring holds them all). Per worker count:

  stored        frames stored during the run (the ring's write count)
  dropped       frames the camera worker dropped during the run: every process was busy
  missing ids   frame ids absent from the run's frames (should equal dropped)
  in order      whether the frame ids only increase (the pool returns results in order)
  processes     distinct processes the hook ran in (read from the pixels: the hook is
                slow_hooks:sleep_60ms_pid, which writes its pid into row 24)
  delay         t_stored - t_capture, ms (median, p99): the hook's 60 ms plus the wait for
                a process and the copies

With one process the hook cannot keep up (about 1 frame in 6 is dropped at 20 fps); with
three, none should be on an idle machine. tests/integration/test_processing.py asserts the
order, the spreading and that a dropped frame is counted; how many are dropped is this
bench's figure. Writes hook_rate.json into --out. Exit status 0 if every run kept the order
and counted every missing frame as dropped; 1 otherwise; 2 on bad flags.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

if not __package__:  # run as a script (python bench/cameras/hook_rate.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common

BENCH_DIR = os.path.dirname(os.path.abspath(__file__))
HOOK = "slow_hooks:sleep_60ms_pid"
HOOK_COST_MS = 60.0
PID_ROW = 24


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    p.add_argument("--workers", type=common.int_list, default=[1, 3], help="process_workers of each run")
    p.add_argument("--fps", type=common.positive_float, default=20.0)
    p.add_argument("--seconds", type=common.positive_float, default=30.0, help="length of each run")
    p.add_argument("--warmup", type=common.nonnegative_float, default=2.0, help="seconds before a run counts")
    p.add_argument("--timeout", type=float, default=5.0, metavar="S", help="client timeout per request")
    p.add_argument("--out", default=common.DEFAULT_OUT, metavar="DIR", help="folder for hook_rate.json and logs")
    return p


def pid_of(image) -> int:
    return int.from_bytes(bytes(image[PID_ROW, :4]), "little")


def measure(args, workers: int, out: str) -> dict:
    camera = f"a=synthetic:fps={args.fps:g},width=64,height=48,process={HOOK},process_workers={workers}"
    slots = int(args.fps * (args.seconds + args.warmup)) + 50  # the whole run stays in the ring
    log_path = os.path.join(out, f"hook_rate.{workers}.service.log")
    with common.service(None, ["--camera", camera, "--slots", str(slots)], log_path, args.timeout) as (client, info):
        common.wait_until_streaming(client, min_frames=3, timeout=30)
        time.sleep(args.warmup)
        before, start = client.status()["cameras"]["a"], client.time()
        time.sleep(args.seconds)
        after, end = client.status()["cameras"]["a"], client.time()
        frames = client.sequence("range", camera="a", start=start, end=end - 200_000_000)  # surely stored
    ids = [f.frame_id for f in frames]
    return {
        "workers": workers,
        "service": info,
        "stored": after["frames_stored"] - before["frames_stored"],
        "dropped": after["frames_dropped"] - before["frames_dropped"],
        "hook_errors": after["hook_errors"] - before["hook_errors"],
        "frames": len(ids),
        "missing_ids": (ids[-1] - ids[0] + 1 - len(ids)) if ids else 0,
        "in_order": all(b > a for a, b in zip(ids, ids[1:])),
        "processes": len({pid_of(f.image) for f in frames}),
        "delay_ms": common.summary(common.ms(f.t_stored - f.t_capture) for f in frames),
    }


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = common.parse_args(p, argv)
    if isinstance(args, int):
        return args
    if 0 in args.workers:
        return common.usage_error(p, "--workers must be 1 or more")
    out = common.ensure_dir(args.out)
    os.environ["PYTHONPATH"] = BENCH_DIR + os.pathsep + os.environ.get("PYTHONPATH", "")
    host = common.host_info()
    runs = [measure(args, n, out) for n in args.workers]
    print(common.code_line(host["code"]))
    print(
        f"hook_rate: one synthetic camera at {args.fps:g} fps, a {HOOK_COST_MS:g} ms hook ({HOOK}) over "
        f"process_workers processes, {args.seconds:g} s per run"
    )
    rows = [
        [
            f"{r['workers']} process(es)",
            r["stored"],
            r["dropped"],
            r["missing_ids"],
            "yes" if r["in_order"] else "NO",
            r["processes"],
            r["hook_errors"],
            r["delay_ms"]["median"],
            r["delay_ms"]["p99"],
        ]
        for r in runs
    ]
    print(
        common.table(
            ["run", "stored", "dropped", "missing ids", "in order", "processes", "hook errors", "delay med", "p99"],
            rows,
            digits=1,
        )
    )
    print("dropped: frames_dropped during the run; missing ids: ids absent from the run's frames; delay: ms")
    failed = [r for r in runs if not r["in_order"] or r["missing_ids"] > r["dropped"] or r["hook_errors"]]
    json_path = os.path.join(out, "hook_rate.json")
    common.write_json(
        json_path,
        {"benchmark": "hook_rate", "settings": vars(args), "host": host, "hook": HOOK, "runs": runs},
    )
    print(f"wrote {json_path}")
    return common.EXIT_FAILED if failed else common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
