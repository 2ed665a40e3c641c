"""Compare: what moving camera frames costs through this service versus the alternatives,
in one run, with the same frames for every contender.

Per scenario (--scenarios; default all: 2x1360x1024 = 2 synthetic mono8 cameras of 1360x1024,
4x1360x1024, 2x2048x2048) a service is launched (`fxis run`, the scenario's cameras at 20 fps,
rings of --slots, tcp loopback). Ten tuples are taken from it once (the "source": copies of
their frames, each tuple in its own arrays, cycled through so that the source is as cold as a
ring's slots) and then these contenders are timed, -n samples each after --warmup unrecorded
ones, INTERLEAVED: every round times one sample of each contender in a random order, after a
random sleep U[0, --sleep-max-ms] ms before each sample, so a drift of this machine's speed
hits all of them alike.

  fxis tuple tcp     Client(tcp, local="off").tuple(at=now - 150 ms): t* lies in the past, its
                     frames are stored, nothing is waited for (bench and service share
                     CLOCK_MONOTONIC on one host); the frames travel in the ZeroMQ reply.
  fxis tuple local   the same with local="require": the same-host client answers from the
                     shared-memory rings itself (no message to the coordinator) and copies
                     the frames out (into buffers of its pool).
  ... zero-copy      the same with copy=False: read-only views of the ring slots, no copy.
  fxis latest local  client.latest() on the local path: the newest frame of every camera,
                     copied; and with copy=False (zero-copy).
  fxis time round    client.time(): the smallest round trip to the coordinator, no frames.
  trip (tcp)
  imagezmq           an ImageHub in a child process receives and replies b"OK"; one sample =
                     the ImageSender sending the N frames of a source tuple (N sequential
                     send_image round trips, tcp loopback). Also shown per image (sample / N).
  imagezmq 1 image   the same with one image per sample (cycling through every source frame).
  ZeroMQ reply,      the floor of fxis's own network design: a ROUTER in a child process answers
  frames copied      each request with a small header and the N frames of a source tuple, each
  once               copied once into its message, as the coordinator copies out of a ring (and
                     nothing else); one sample = the request and the reply's frames as arrays.
  mp.Queue           a child process that, for each request put on one multiprocessing.Queue,
                     puts the N frames of a source tuple (a list of arrays) on a reply queue;
                     one sample = request + get of the N frames.
  plain copy         the floor: frame.copy() of the N frames of a source tuple (fresh arrays,
                     which page-fault on first touch).
  copy reused        the other floor: np.copyto of the same frames into preallocated arrays.

Then the hot loop (--hot-calls, default 1000): each contender called back to back, without
sleeps, its caches and threads warm, in 10 blocks whose order among the contenders is random
in every round; each call is timed on its own and its check runs untimed after it.

Then the tcp service is stopped and the same cameras are served on an ipc endpoint
(ipc:///tmp/fxis-compare-<pid>.sock), where "fxis tuple ipc" (local="off") is timed, interleaved
with the plain copy again as a control of the machine's speed between the two phases.

Every fxis sample must come by the path asked for (FrameTuple.path), hold every camera, and
carry the synthetic cameras' pixel stamp (checked outside the timed call; zero-copy views must
still be valid then). A sample that raises is recorded with its error and counted, never raised.

Prints one table per scenario (median and p99 in ms; "faults": the median count of minor page
faults the bench process took during a sample, which shows whether fresh arrays were faulted in
or came from memory the allocator had kept mapped; "hot ms": the hot loop's median; and the
median's ratio to the plain copy, to the reused-buffer copy, to the `time` round trip, to
imagezmq per tuple of N images and to imagezmq for ONE image), then the targets of issue 23,
PASS/FAIL with the ratios, on scenario 2x1360x1024 (the interleaved medians of the same run
decide; the hot loop's ratios are shown beside them, with their own verdict):
  - local tuple and local latest, copied: <= 1.3x the plain copy of the same frames;
  - local tuple, zero-copy: <= 0.3x the `time` round trip; local latest, zero-copy: <= 0.2x;
  - tuple over tcp: <= 2.0x imagezmq's round trip for ONE image, and <= 1.2x imagezmq
    carrying the same N images.
Writes compare.json (settings, seed, host, every raw sample) and compare.png (median per
contender with p99 whiskers, one group per scenario) into --out, and the services' logs.
Exit status: 0 when every contender had answered samples (whatever the targets say); 1 if a
service did not start or stream, or every sample of some contender failed; 2 on bad flags.

The pieces: ours.py (fxis's contenders, the tcp and ipc phases), rivals.py
(imagezmq, mp.Queue, the copies), report.py (tables, targets, figure), bench/shared/interleave.py
(the interleaved timing).
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import time

if not __package__:  # run as a script (python bench/compare/peers.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.compare import report
from bench.compare.ours import IPC, SCENARIOS, ipc_phase, tcp_phase
from bench.compare.rivals import COPY, COPY_CONTROL, IMZ, IMZ_PER_IMAGE
from bench.shared import common
from bench.shared.interleave import median, result_of

# ---- command line ----------------------------------------------------------------------------


def scenario_list(text: str) -> list[str]:
    names = [v.strip() for v in text.split(",") if v.strip()]
    unknown = [n for n in names if n not in SCENARIOS]
    if not names or unknown:
        raise argparse.ArgumentTypeError(f"expected a comma-separated subset of {', '.join(SCENARIOS)}, got {text!r}")
    return list(dict.fromkeys(names))


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    common.add_pacing_args(
        p, "of each contender per scenario", count=300, warmup=10, sleep_max_ms=5.0, flag="--samples", what="sample"
    )
    p.add_argument(
        "--hot-calls",
        type=int,
        default=1000,
        help="then this many back-to-back calls of each contender (the hot loop; 0: none)",
    )
    p.add_argument(
        "--scenarios", type=scenario_list, default=list(SCENARIOS), help="comma-separated: " + ", ".join(SCENARIOS)
    )
    p.add_argument("--slots", type=common.positive_int, default=20, help="frames per camera ring")
    common.add_output_args(p.add_argument_group("output"), seed_help="seed of the order and sleeps")
    return p


# ---- one scenario ----------------------------------------------------------------------------


def per_image(result: dict, n: int) -> dict:
    """imagezmq's N-image samples (and hot-loop calls) divided by N."""
    samples = [v / n if v is not None else None for v in result["samples_ms"]]
    hot = [v / n if v is not None else None for v in result["hot_samples_ms"]]
    return {
        **result,
        "summary_ms": common.summary(v for v in samples if v is not None),
        "samples_ms": samples,
        "hot_ms": common.summary(v for v in hot if v is not None),
        "hot_samples_ms": hot,
        "derived": f"{IMZ} samples / {n}",
        "minor_faults_median": None,
    }


def run_scenario(args, scenario: str, rng, out: str) -> tuple[dict, dict]:
    """Both phases of one scenario: (results by contender, facts about it)."""
    tcp_contenders, tcp_info, source = tcp_phase(args, scenario, rng, out)
    ipc_contenders, ipc_info = ipc_phase(args, scenario, rng, out, source)
    results = {c.name: result_of(c) for c in tcp_contenders + ipc_contenders}
    results[IMZ_PER_IMAGE] = per_image(results[IMZ], len(source[0]))
    return results, {"tcp": tcp_info, "ipc": ipc_info, "source_tuples": len(source)}


def report_errors(results: dict) -> None:
    for name, r in results.items():
        if r["failed"]:
            print(f"  {name}: {r['failed']} failed samples, first: {r['errors'][0][1]}")
            if r["summary_ms"]["n"] == 0 and r["first_traceback"]:
                print("    " + r["first_traceback"].rstrip().replace("\n", "\n    "))


# ---- main ------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parsed = common.parse_args_and_out(parser(), argv)
    if isinstance(parsed, int):
        return parsed
    args, out = parsed
    rng = random.Random(args.seed)
    started = time.time()
    host = common.host_info()
    print(common.code_line(common.code_version()))
    all_results, facts, broken = {}, {}, {}
    for scenario in args.scenarios:
        try:
            all_results[scenario], facts[scenario] = run_scenario(args, scenario, rng, out)
        except RuntimeError as exc:  # a service or child that did not start or stream
            broken[scenario] = common.describe_error(exc)
            print(f"compare: {scenario}: {broken[scenario]}", file=sys.stderr)
            continue
        print()
        print(report.scenario_table(scenario, all_results[scenario], SCENARIOS[scenario][0]))
        control = median(all_results[scenario], COPY_CONTROL)
        print(
            f"({IPC} ran on its own service after the others; the plain copy timed beside it: "
            f"median {common.fmt(control, 3)} ms, vs {common.fmt(median(all_results[scenario], COPY), 3)} "
            "ms in the main phase)"
        )
        report_errors(all_results[scenario])
    tlist = report.targets(all_results)
    print()
    print(report.targets_table(tlist))
    empty = [f"{s}: {name}" for s, res in all_results.items() for name, r in res.items() if r["summary_ms"]["n"] == 0]
    for e in empty:
        print(f"every sample failed: {e}")

    json_path, png_path = os.path.join(out, "compare.json"), os.path.join(out, "compare.png")
    common.write_json(
        json_path,
        {
            **common.run_record("compare", started, argv, args),
            "seed": args.seed,
            "host": host,
            "clock": "samples are time.perf_counter_ns() around the timed call, in ms; None = failed",
            "scenarios": {
                s: {
                    "cameras": SCENARIOS[s][0],
                    "width": SCENARIOS[s][1],
                    "height": SCENARIOS[s][2],
                    **facts[s],
                    "contenders": all_results[s],
                }
                for s in all_results
            },
            "broken_scenarios": broken,
            "targets": tlist,
        },
    )
    if all_results:
        report.plot(
            all_results,
            png_path,
            f"compare: median and p99 per contender, {args.samples} samples each, seed {args.seed}",
        )
        print(f"wrote {json_path} and {png_path}")
    else:
        print(f"wrote {json_path}")
    return common.EXIT_FAILED if broken or empty else common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
