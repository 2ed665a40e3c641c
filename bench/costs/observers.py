"""Observer cost: what watching the cameras costs the service, idle vs with an observer.

Launches a service with --cameras synthetic mono8 cameras (or measures the one at
--endpoint, on this host), then runs one phase per observer: first none ("idle"), then
each of --observers in turn. An observer is a process started next to the service (a
recording, say) and stopped with SIGINT after the phase. Each phase waits --warmup
seconds, then reads the CPU time of every process of the service (supervisor,
coordinator, each camera worker, from /proc/PID/stat) and of the observer over
--seconds: percent of one core.

Observers (OBSERVERS below; another one, a dashboard viewer say, is one more entry: a
name, a line of text and the command that starts it):
  record        fxis record, every frame raw (sensor_msgs/Image) into a bag in a temp folder
  record-jpeg   fxis record --encoding jpeg
  record-tuples fxis record --tuples (one synchronized tuple per step)
  record-h264   fxis record --codec h264 (and record-h265, record-av1): video, default settings

Prints a table (rows: processes; columns: phases), then each observer's own report (for
`fxis record`: frames, missed and dropped by camera per camera, the losses of a recording on
this machine, which tests/integration/test_record.py does not assert to be 0: it asserts that
each one is reported), and writes observer_cost.json (settings, host, per phase the CPU
percent of each process, the observer's own output) into --out.
Exit status 0 when every phase ran; 1 if the service did not stream or an observer failed;
2 on bad flags.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass

if not __package__:  # run as a script (python bench/costs/observers.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common
from bench.shared.cpu import cpu_percent, cpu_sample, service_processes

IDLE = "idle"
OBSERVER = "observer"  # the CPU row of the observer process itself
STOP_TIMEOUT_S = 30.0


@dataclass(frozen=True)
class Observer:
    what: str
    command: Callable[[str, str], list[str]]  # (service endpoint, scratch folder) -> argv


def fxis_record(*flags: str) -> Callable[[str, str], list[str]]:
    return lambda endpoint, scratch: [
        sys.executable,
        "-m",
        "fxis_shm.cli",
        "record",
        "--endpoint",
        endpoint,
        "--out",
        os.path.join(scratch, "bag"),
        *flags,
    ]


OBSERVERS = {
    "record": Observer("fxis record, every frame raw", fxis_record()),
    "record-jpeg": Observer("fxis record --encoding jpeg", fxis_record("--encoding", "jpeg")),
    "record-tuples": Observer("fxis record --tuples", fxis_record("--tuples")),
    **{
        f"record-{codec}": Observer(
            f"fxis record --codec {codec} (default encoder, CRF, preset)", fxis_record("--codec", codec)
        )
        for codec in ("h264", "h265", "av1")
    },
}


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    p.add_argument(
        "--observers",
        nargs="+",
        choices=list(OBSERVERS),
        default=["record"],
        help="the observers to measure, one phase each, after the idle phase",
    )
    p.add_argument("--cameras", type=common.positive_int, default=2, help="synthetic cameras of a launched service")
    p.add_argument("--fps", type=common.positive_float, default=20.0)
    p.add_argument("--size", default="1360x1024", metavar="WxH", help="image size of the cameras")
    p.add_argument("--warmup", type=common.nonnegative_float, default=2.0, help="seconds before each measurement")
    p.add_argument("--seconds", type=common.positive_float, default=10.0, help="seconds each phase is measured")
    common.add_service_args(p, "its processes must be on this host (their CPU is read from /proc)")
    return p


def measure(procs: dict[str, int], seconds: float, observer_pid: int | None = None) -> dict:
    """CPU percent of one core of every process over ``seconds``."""
    watched = {**procs, **({OBSERVER: observer_pid} if observer_pid else {})}
    t0, before = time.monotonic(), cpu_sample(watched)
    time.sleep(seconds)
    return cpu_percent(before, cpu_sample(watched), time.monotonic() - t0)


def run_phase(name: str, endpoint: str, procs: dict[str, int], args) -> dict:
    """One observer (or none, for ``idle``) running while the service's CPU is measured."""
    if name == IDLE:
        time.sleep(args.warmup)
        return {"cpu_percent": measure(procs, args.seconds)}
    with tempfile.TemporaryDirectory(prefix="observer_cost.") as scratch:
        proc = subprocess.Popen(
            OBSERVERS[name].command(endpoint, scratch), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        try:
            time.sleep(args.warmup)
            if proc.poll() is not None:
                raise RuntimeError(f"observer {name!r} exited early: {proc.stderr.read().strip()}")
            cpu = measure(procs, args.seconds, proc.pid)
            proc.send_signal(signal.SIGINT)
            out, err = proc.communicate(timeout=STOP_TIMEOUT_S)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        if proc.returncode not in (0, 130):  # 130: ended by the SIGINT sent above, its bag kept
            raise RuntimeError(f"observer {name!r} failed (exit {proc.returncode}): {err.strip()}")
    return {"cpu_percent": cpu, "output": out}


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = common.parse_args(p, argv)
    if isinstance(args, int):
        return args
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        return common.usage_error(p, f"--size must be WIDTHxHEIGHT, got {args.size!r}")
    names = [f"cam{i}" for i in range(args.cameras)]
    run_args = common.synthetic_camera_flags(names, args.fps, width, height)
    out = common.ensure_dir(args.out)
    phases: dict[str, dict] = {}
    try:
        with common.service(args.endpoint, run_args, os.path.join(out, "observer_cost.service.log"), args.timeout) as (
            client,
            info,
        ):
            status = common.wait_until_streaming(client)
            procs = service_processes(status, status["supervisor"]["pid"])
            for name in [IDLE, *args.observers]:
                print(
                    f"phase {name}: {args.warmup:g} s warm-up, {args.seconds:g} s measured ...",
                    file=sys.stderr,
                    flush=True,
                )
                phases[name] = run_phase(name, info["endpoint"], procs, args)
    except (RuntimeError, common.FxisError) as exc:
        print(f"observers.py: {common.describe_error(exc)}", file=sys.stderr)
        return common.EXIT_FAILED
    rows = sorted({row for phase in phases.values() for row in phase["cpu_percent"]}, key=lambda r: (r == OBSERVER, r))
    print(
        common.table(
            ["process (% of a core)", *phases],
            [[row, *(phases[ph]["cpu_percent"].get(row) for ph in phases)] for row in rows],
            title=f"{args.cameras} camera(s) {width}x{height} at {args.fps:g} fps, {args.seconds:g} s per phase",
            digits=1,
        )
    )
    for name in args.observers:
        print(f"\n{name}: its own report\n{phases[name]['output'].rstrip()}")
    print(common.code_line(common.code_version()))
    common.write_json(
        os.path.join(out, "observer_cost.json"),
        {
            "settings": vars(args),
            "host": common.host_info(),
            "service": info,
            "observers": {n: OBSERVERS[n].what for n in args.observers},
            "phases": phases,
        },
    )
    return common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
