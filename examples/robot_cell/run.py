"""The robotic cell of the paper's Fig. 1, on one host: an acquisition service
with a synthetic stereo pair, a vision node and a robot.

    python examples/robot_cell/run.py                       # 1360x1024 mono8, 20 fps, 20 requests
    python examples/robot_cell/run.py --width 640 --height 480 -n 5

It starts the service (``fxis run`` with cameras ``left`` and ``right`` showing
a chessboard, ``right`` shifted by ``--shift`` px), then ``vision.py`` (and
waits for its ``ready`` line), then runs the robot in this process. It prints
one line per result and a summary, stops everything, and exits 0 only if every
request got a result, none was an error, and the measured disparity is within
1 px of ``--shift``.
"""

from __future__ import annotations

import argparse
import os
import select
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import robot

from fxis_shm import RequestTimeout
from fxis_shm.service.launch import ServiceProcess, free_tcp_port

HERE = Path(__file__).resolve().parent


def wait_for_line(proc: subprocess.Popen, expected: str, timeout: float) -> None:
    """Read ``proc``'s stdout until the line ``expected``; raise if it exits or the deadline passes."""
    deadline = time.monotonic() + timeout
    fd = proc.stdout.fileno()
    buffer = b""
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            raise RuntimeError(f"vision.py did not say {expected!r} within {timeout} s")
        ready, _, _ = select.select([fd], [], [], left)
        if not ready:
            continue
        chunk = os.read(fd, 4096)
        if not chunk:
            proc.wait(timeout=5)
            raise RuntimeError(f"vision.py exited with code {proc.returncode} during start-up")
        buffer += chunk
        if expected.encode() in buffer.splitlines():
            return


def stop_process(proc: subprocess.Popen, timeout: float = 5.0) -> int:
    """SIGTERM, wait, then kill; returns the exit code."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode


def _raise_on_sigterm(signum, frame):
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise KeyboardInterrupt  # runs the clean-up below like Ctrl-C does


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("-n", type=int, default=20, help="requests the robot publishes (default 20)")
    p.add_argument("--width", type=int, default=1360, help="image width (default 1360)")
    p.add_argument("--height", type=int, default=1024, help="image height (default 1024)")
    p.add_argument("--fps", type=float, default=20.0, help="frames per second (default 20)")
    p.add_argument("--shift", type=int, default=24, help="shift_px of the right camera: the disparity (default 24)")
    p.add_argument(
        "--sleep",
        type=float,
        nargs=2,
        default=(0.13, 0.23),
        metavar=("A", "B"),
        help="seconds between requests, uniform in [A, B] (default 0.13 0.23)",
    )
    p.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for each result (default 10)")
    p.add_argument("--seed", type=int, help="seed of the robot's random sleeps")
    p.add_argument("--name", default=f"robotcell{os.getpid()}", help="service name (names its shared memory)")
    p.add_argument("-v", "--verbose", action="store_true", help="vision logs every pair; service log shown")
    args = p.parse_args(argv)
    signal.signal(signal.SIGTERM, _raise_on_sigterm)

    camera = f"synthetic:pattern=chessboard,fps={args.fps},width={args.width},height={args.height}"
    results = f"tcp://127.0.0.1:{free_tcp_port()}"
    service_log = None if args.verbose else tempfile.TemporaryFile()
    svc = ServiceProcess(
        ["--camera", f"left={camera}", "--camera", f"right={camera},shift_px={args.shift}"],
        name=args.name,
        stderr=service_log,
    )
    vision = None
    code = 1
    try:
        svc.start()
        print(
            f"service {svc.name!r}: cameras left, right ({args.width}x{args.height} mono8, "
            f"{args.fps:g} fps, right shifted by {args.shift} px); events {svc.events}, pub {svc.pub}",
            flush=True,
        )
        vision = subprocess.Popen(
            [
                sys.executable,
                str(HERE / "vision.py"),
                "--pub",
                svc.pub,
                "--events",
                svc.events,
                "--results",
                results,
                "--exit-with-parent",
                *(["-v"] if args.verbose else []),
            ],
            stdout=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
        )
        wait_for_line(vision, "ready", timeout=15)
        print(f"vision node ready: results on {results}", flush=True)
        outcomes = robot.run(
            svc.events,
            svc.pub,
            results,
            args.n,
            tuple(args.sleep),
            args.timeout,
            seed=args.seed,
            out=lambda line: print(line, flush=True),
        )
        for line in robot.summary(outcomes):
            print(line)
        answered = [o for o in outcomes if o.ok]
        if len(answered) != len(outcomes):
            print(f"FAIL: {len(outcomes) - len(answered)} of {len(outcomes)} requests got no result")
        else:
            worst = max(abs(o.result["disparity_px"] - args.shift) for o in answered)
            verdict = "OK" if worst <= 1.0 else "FAIL"
            print(
                f"{verdict}: every request got a result; disparity off shift_px={args.shift} by at most {worst:.3f} px"
            )
            code = 0 if verdict == "OK" else 1
    except (RuntimeError, RequestTimeout) as exc:
        print(f"FAIL: {exc}")
        if service_log is not None:
            service_log.seek(0)
            tail = service_log.read().decode(errors="replace").splitlines()[-20:]
            print("service log (last lines):", *tail, sep="\n  ")
    except KeyboardInterrupt:
        print("interrupted")
        code = 130
    finally:
        if vision is not None:
            rc = stop_process(vision)
            if rc != 0:
                print(f"vision.py exited with code {rc}")
                code = code or 1
        svc.stop()
        if service_log is not None:
            service_log.close()
    return code


if __name__ == "__main__":
    sys.exit(main())
