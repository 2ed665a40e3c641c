"""The networked case (issue 11): a client on another host, with a clock of its own, over a
rate-limited link; a tuple of cameras on two hosts; raw against JPEG frames; how late t* would
be without the call moment. This file is the driver; each part is a module bench/_network_*.py.

The other hosts are emulated (tests/hosts.py): network namespaces on veth links shaped with
tc's token bucket (no added delay: this kernel has no netem), each with its own
CLOCK_MONOTONIC (a time namespace, ahead of ours by --offset-s, so the true offset is known
exactly) and /dev/shm, addresses of TEST-NET-2, services with CurveZMQ keys. Needs root.

Host A (clock +offset) runs cam0 and cam1, as bench/latency/paper.py's service (20 fps, 1360x1024
mono8, phases 0 and 1 ms, jitter +/-0.3 ms, 20 slots); host B (clock +2*offset) runs cam2.
This process is the client, on the root namespace's clock. Parts (--parts):

  table2  the paper's Table II (bench/latency/experiment.py's request and metrics, its sleeps and
          spike rule), policy "ours" unless --policies says otherwise, for three configurations:
          one host (the same cameras served on this host; the client reads locally), remote raw
          and remote JPEG (host A over 1 Gbit). --requests rounds; in each round every
          configuration, after its own random sleep, calls at the same phase of its cameras'
          frame period (drawn per round), so the configurations are compared request by request
          (paired) rather than by means that wander over a frame period. Target: the remote
          means of eps_b, |eps_j| and tau_w within 0.5 ms of the one host's (paired mean
          difference, printed with its standard error); 0 spikes.
  tuples  --tuple-requests tuples of cam0 (host A) and cam2 (host B) through one client over
          both services, each after a sleep U[0, 2 x --tuple-sleep-ms]. The true skew comes
          from the services' own stamps and the exact offsets; the least the cameras allow is
          the shortest arc of the frame period covering their phases as observed in true time
          (bench/latency/paper.py's definition; the two services start at different moments, so
          their relative phase is whatever it is). Target: 0 spikes (true skew > least + 2 ms).
  size    round trip and bytes per tuple of cam0+cam1 (wait="none") raw and JPEG (--quality)
          over 1 Gbit and 100 Mbit, --size-requests each. Bytes: what the link carried from
          host A (the shaper's counter: TCP, CurveZMQ and headers included) per request.
          Targets: JPEG/raw mean round trip <= 0.6x on 1 Gbit, <= 0.25x on 100 Mbit.
  travel  how late t* would be if it were the request's arrival instead of the call moment
          (issue 11; bench/network/travel.py): arrival - call per link (1 Gbit, 100 Mbit), load
          (idle; busy: another client pulling raw tuples back to back) and encoding,
          --travel-requests calls tuple(wait="none") each after a sleep U[0, 2 x
          --travel-sleep-ms]. Target: t_request equals the call moment within the clock
          estimate's uncertainty, every call.
  clock   (always) every client's clock estimate against the true offset, sampled every
          --clock-every s from the first remote client on, while the other parts run; after
          them the client keeps asking host A for tuples at the paper's pace until --minutes
          have passed. Error = the estimate's mapping of "now" minus the true one.
          Target: p99 |error| <= 0.1 ms.

Prints a table per part with PASS/FAIL per target; writes network.json to --out, and the
services' logs to network-logs/ and network.local.log there.
Exit status: 0 when the run completed; 1 if a request failed (or, with --strict, a target
failed; or emulated hosts cannot be made here); 2 on bad flags.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import random
import shutil
import sys
import time

if not __package__:  # run as a script (python bench/network/remote.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.latency import experiment as paper
from bench.network.clock import ClockWatch, print_clock
from bench.network.size import sizes
from bench.network.table2 import compare_table_ii, table_ii
from bench.network.travel import travel
from bench.network.tuples import two_host_tuples
from bench.shared import common
from fxis_shm import Client
from tests.hosts import HostsUnavailable, Lab

PARTS = ("table2", "tuples", "size", "travel")


def parse_parts(text: str) -> list[str]:
    names = [x.strip() for x in text.split(",") if x.strip()]
    unknown = [x for x in names if x not in PARTS]
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown part(s) {', '.join(unknown)}: use {', '.join(PARTS)}")
    return names


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    p.add_argument("--parts", type=parse_parts, default=",".join(PARTS), help="comma list of " + ", ".join(PARTS))
    p.add_argument(
        "--minutes",
        type=common.positive_float,
        default=5.0,
        help="the clock estimate is watched for at least this long (the target: 5)",
    )
    p.add_argument("--clock-every", type=common.positive_float, default=0.5, help="clock samples every S s")
    p.add_argument(
        "--offset-s",
        type=common.positive_int,
        default=1000,
        help="host A's clock is this many seconds ahead of ours, host B's twice as many",
    )
    p.add_argument("--quality", type=common.int_between(1, 100), default=90, help="JPEG quality")
    t2 = p.add_argument_group("table2 (as bench/latency/paper.py)")
    t2.add_argument(
        "-n",
        "--requests",
        type=common.positive_int,
        default=300,
        help="rounds, each one request per configuration (the paper: 100 requests; tau_w "
        "spreads over a frame period, so telling 0.5 ms apart takes a few hundred)",
    )
    t2.add_argument("--sleep-ms", type=common.nonnegative_float, default=180.0, help="tau_sleep, ms")
    t2.add_argument("--fluct-ms", type=common.nonnegative_float, default=50.0, help="tau_mf, ms")
    t2.add_argument(
        "--policies", type=paper.parse_policies, default="ours", help="comma list of paper, ours (or 'both')"
    )
    tu = p.add_argument_group("tuples")
    tu.add_argument("--tuple-requests", type=common.positive_int, default=1000)
    tu.add_argument(
        "--tuple-sleep-ms",
        type=common.nonnegative_float,
        default=40.0,
        help="mean sleep before each two-host tuple, ms",
    )
    tr = p.add_argument_group("travel")
    tr.add_argument(
        "--travel-requests", type=common.positive_int, default=100, help="calls per link, load and encoding"
    )
    tr.add_argument(
        "--travel-sleep-ms", type=common.nonnegative_float, default=50.0, help="mean sleep before each call, ms"
    )
    p.add_argument("--size-requests", type=common.positive_int, default=20, help="requests per size configuration")
    cams = p.add_argument_group("cameras")
    cams.add_argument("--fps", type=common.positive_float, default=20.0)
    cams.add_argument("--jitter-ms", type=common.nonnegative_float, default=0.3)
    common.add_frame_size_args(cams, 1360, 1024)
    cams.add_argument("--slots", type=common.positive_int, default=20)
    p.add_argument("--strict", action="store_true", help="exit 1 if a target fails")
    common.add_output_args(p)
    return p


# ---- main -----------------------------------------------------------------------------------


def keep_asking(args, client: Client, cams: list[str], watch: ClockWatch, rng: random.Random) -> int:
    """Tuples at the paper's pace until the clock has been watched for --minutes; returns failures."""
    failed = 0
    while watch.elapsed_s() < args.minutes * 60:
        common.sleep_ms(args.sleep_ms + rng.uniform(-args.fluct_ms, args.fluct_ms))
        try:
            client.tuple(cams)
        except common.REQUEST_ERRORS:
            failed += 1
    return failed


def main(argv: list[str] | None = None) -> int:
    parsed = common.parse_args_and_out(parser(), argv)
    if isinstance(parsed, int):
        return parsed
    args, out = parsed
    rng = random.Random(args.seed)
    names = ["cam0", "cam1"]
    exp = paper.Experiment(names, args.fps, [0.0, 1.0], args.jitter_ms)
    cam_flags = common.synthetic_camera_flags(names, args.fps, args.width, args.height, [0.0, 1.0], args.jitter_ms) + [
        "--slots",
        str(args.slots),
    ]
    host_info, started = common.host_info(), time.time()
    result = {
        **common.run_record("network", started, argv, args),
        "host": host_info,
        "experiment": exp.as_dict(),
        "targets": {},
    }
    watch = ClockWatch(args.clock_every)
    failed = 0
    print(
        f"network: client on this host; host A clock +{args.offset_s} s (cam0, cam1), host B clock "
        f"+{2 * args.offset_s} s (cam2); links 1 Gbit unless said; seed {args.seed}"
    )
    print(common.code_line(host_info["code"]))
    try:
        with contextlib.ExitStack() as stack:
            logs = os.path.join(out, "network-logs")  # the emulated hosts' service logs, of this run only
            shutil.rmtree(logs, ignore_errors=True)
            lab = stack.enter_context(Lab(log_dir=common.ensure_dir(logs)))
            stack.callback(watch.stop)
            a = lab.host(clock_offset_s=args.offset_s, rate="1gbit")
            svc_a = a.service(*cam_flags)
            remote = {
                enc: stack.enter_context(
                    Client(
                        svc_a.endpoint, timeout=args.timeout, keys=lab.client_keys, encoding=enc, quality=args.quality
                    )
                )
                for enc in ("raw", "jpeg")
            }
            for enc, client in remote.items():
                watch.watch(f"A {enc}", client, svc_a.endpoint, a.clock_offset_ns)
            status = common.wait_until_streaming(remote["raw"])
            kinds_of = {cam: c["kind"] for cam, c in status["cameras"].items()}
            if "table2" in args.parts:
                with common.service(None, cam_flags, os.path.join(out, "network.local.log"), args.timeout) as (
                    local,
                    _,
                ):
                    common.wait_until_streaming(local)
                    t2 = table_ii(
                        args,
                        {"one host": local, "remote raw": remote["raw"], "remote jpeg": remote["jpeg"]},
                        exp,
                        kinds_of,
                        rng,
                    )
                result["table2"] = t2
                result["targets"]["table2"] = compare_table_ii(t2, args.policies, exp)
                failed += sum(r[pol]["failed"] for r in t2.values() for pol in args.policies)
            if "tuples" in args.parts:
                b = lab.host(clock_offset_s=2 * args.offset_s, rate="1gbit")
                svc_b = b.service(
                    *common.synthetic_camera_flags(["cam2"], args.fps, args.width, args.height, [0.0], args.jitter_ms),
                    "--slots",
                    str(args.slots),
                )
                both = stack.enter_context(
                    Client([svc_a.endpoint, svc_b.endpoint], timeout=args.timeout, keys=lab.client_keys)
                )
                watch.watch("A+B", both, svc_a.endpoint, a.clock_offset_ns)
                watch.watch("A+B", both, svc_b.endpoint, b.clock_offset_ns)
                common.wait_until_streaming(both.clients[1])
                result["tuples"] = two_host_tuples(
                    args, both, {"cam0": a.clock_offset_ns, "cam2": b.clock_offset_ns}, rng
                )
                result["targets"]["tuples"] = result["tuples"]["passed"]
                failed += result["tuples"]["failed"]
            if "size" in args.parts:
                result["size"] = sizes(args, a, remote, names)
                result["targets"]["size"] = result["size"]["targets"]
            if "travel" in args.parts:
                result["travel"] = travel(args, a, svc_a.endpoint, lab.client_keys, remote, names, rng)
                result["targets"]["travel"] = result["travel"]["targets"]
                failed += sum(r["failed"] for r in result["travel"]["configs"].values())
            failed += keep_asking(args, remote["raw"], names, watch, rng)
            watch.stop()
            result["clock"] = watch.report()
            result["clock_samples"] = watch.samples
            result["targets"]["clock"] = result["clock"]["target"]
            print()
            print_clock(result["clock"], args.minutes)
    except HostsUnavailable as exc:
        print(f"network: emulated hosts unavailable: {exc}", file=sys.stderr)
        return common.EXIT_FAILED
    except RuntimeError as exc:
        print(f"network: {exc}", file=sys.stderr)
        return common.EXIT_FAILED
    result["failed"] = failed
    result["duration_s"] = time.time() - started
    path = os.path.join(out, "network.json")
    common.write_json(path, result)
    print(f"\nfailed requests: {failed}; took {result['duration_s']:.0f} s; wrote {path}")
    if failed:
        return common.EXIT_FAILED
    if args.strict and not all(passed is True for passed in verdicts(result["targets"])):
        return common.EXIT_FAILED
    return common.EXIT_OK


def verdicts(targets: dict) -> list:
    """Every target's ``passed`` (True, False or None: not measured)."""
    flat = []
    for value in targets.values():
        for t in value if isinstance(value, list) else [value]:
            flat.append(t["passed"] if isinstance(t, dict) else t)
    return flat


if __name__ == "__main__":
    sys.exit(main())
