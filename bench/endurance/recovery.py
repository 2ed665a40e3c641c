"""Recovery after kill -9: from the kill to the first successful request.

Launches a service (2 synthetic cameras, 20 fps, 1360x1024) and, --repeat times each,
kills a camera worker and the coordinator with SIGKILL, then requests (every 10 ms,
client timeout 0.2 s) until one succeeds: image() of the killed camera, or tuple() after
the coordinator. The supervisor restarts a process after a 0.5 s backoff (doubling per
restart within 30 s; this bench waits 31 s between kills of the same process unless
--quick). Prints median and max per fault; writes recovery.json into --out.
"""

from __future__ import annotations

import os
import signal
import sys
import time

if not __package__:  # run as a script (python bench/endurance/recovery.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common
from fxis_shm import FxisError
from fxis_shm.service.launch import ServiceProcess


def coordinator_pid(svc: ServiceProcess, timeout: float = 30.0) -> int:
    """The running coordinator's pid (after a kill, once the supervisor has started another)."""
    deadline = time.monotonic() + timeout
    while "coordinator" not in (children := svc.children()):
        if time.monotonic() > deadline:
            raise FxisError(f"no coordinator running after {timeout:.0f} s")
        time.sleep(0.01)
    return children["coordinator"]


def time_to_recover(client, request, timeout: float = 30.0) -> float:
    start = time.monotonic()
    while time.monotonic() - start < timeout:
        try:
            request(client)
            return time.monotonic() - start
        except FxisError:
            time.sleep(0.01)
    raise RuntimeError(f"no successful request within {timeout} s")


def main(argv: list[str] | None = None) -> int:
    p = common.parser_for(__file__, __doc__)
    p.add_argument("--repeat", type=common.positive_int, default=3, help="kills of each kind")
    p.add_argument("--quick", action="store_true", help="do not wait for the backoff to reset between kills")
    p.add_argument("--out", default=common.DEFAULT_OUT)
    args = p.parse_args(argv)
    out = common.ensure_dir(args.out)
    flags = common.synthetic_camera_flags(["cam0", "cam1"], 20.0, 1360, 1024)
    results = {"camera worker": [], "coordinator": []}
    with (
        open(os.path.join(out, "recovery.service.log"), "wb") as log,
        ServiceProcess(flags + ["--restart-limit", str(2 * args.repeat + 2)], stderr=log) as svc,
        svc.client(timeout=0.2) as client,
    ):
        common.wait_until_streaming(client)
        for i in range(args.repeat):
            if i and not args.quick:
                time.sleep(31)  # the supervisor's backoff resets after 30 s of stable running
            os.kill(svc.children()["camera:cam0"], signal.SIGKILL)  # not status: it may take over 0.2 s
            results["camera worker"].append(time_to_recover(client, lambda c: c.image("cam0")))
            os.kill(coordinator_pid(svc), signal.SIGKILL)
            results["coordinator"].append(time_to_recover(client, lambda c: c.tuple()))
    rows = [[fault, len(v), common.summary(v)["median"], max(v)] for fault, v in results.items()]
    print(
        common.table(
            ["kill -9 of", "n", "median s", "max s"],
            rows,
            digits=3,
            title="time from the kill to the first successful request",
        )
    )
    common.write_json(os.path.join(out, "recovery.json"), {"seconds": results, "code": common.code_version()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
