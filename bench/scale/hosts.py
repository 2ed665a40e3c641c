"""Joint tuple streams across two emulated hosts: rate and skew spikes over N tuples.

Makes two emulated camera hosts (tests/hosts.py: network namespaces on TEST-NET-2, clocks
1000 s and 3000 s ahead, 1 Gbit links, CurveZMQ; needs root), one synthetic camera each
(--fps, the second a phase of --phase-ms later), and subscribes to
``Client([a, b]).subscribe().tuples(rate_hz)`` at every --rates value in turn, for -n tuples
each. For every tuple it looks at both services' frame times and computes the least skew any
pair of frames within a period of t* had (true times: each service's stamps less its host's
offset, which the namespaces fix); a spike is a tuple more skewed than that + 2 ms. It prints,
per rate: tuples, rate delivered (by arrival and by the schedule), messages lost (seq gaps),
failed tuples, spikes, and skew median / max.

Exit status 0 if every rate had 0 spikes, 0 failed, 0 lost and the rate within 1 %, 1
otherwise, 2 on bad flags or when hosts cannot be made.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

if not __package__:  # run as a script (python bench/scale/hosts.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))

from fxis_shm import Client
from tests.hosts import HostsUnavailable, Lab

SPIKE_MARGIN_NS = 2_000_000


def least_skew(client: Client, offsets: dict[str, int], t_star: int, period_ns: int) -> int:
    near = []
    for sub in client.clients:
        times = sub.frame_times()
        column = times["columns"].index("t_capture")
        for info in times["cameras"].values():
            true = [row[column] - offsets[sub.endpoint] for row in info["frames"]]
            near.append([t for t in true if abs(t - t_star) <= period_ns])
    left, right = near
    return min(abs(x - y) for x in left for y in right)


def run_rate(client: Client, offsets: dict[str, int], rate_hz: float, n: int, period_ns: int) -> dict:
    skews, spikes, failed, seqs, arrivals, requests = [], 0, 0, [], [], []
    with client.subscribe(timeout=10) as sub:
        sub.tuples(rate_hz=rate_hz)
        while len(seqs) < n:
            message = sub.receive()
            arrivals.append(time.monotonic())
            seqs.append(message.seq)
            if not message.ok:
                failed += 1
                continue
            tup = message.tuple
            requests.append(tup.t_request)
            skews.append(tup.skew_ns)
            if tup.skew_ns > least_skew(client, offsets, tup.t_request, period_ns) + SPIKE_MARGIN_NS:
                spikes += 1
    lost = sum(b - a - 1 for a, b in zip(seqs, seqs[1:]))
    return {
        "rate_hz": rate_hz,
        "tuples": n,
        # from the second message: the first waits for its frames (no lag known yet)
        "delivered_hz": (len(arrivals) - 2) / (arrivals[-1] - arrivals[1]),
        "scheduled_hz": (len(requests) - 1) / ((requests[-1] - requests[0]) / 1e9),
        "lost": lost,
        "failed": failed,
        "spikes": spikes,
        "skew_median_ms": statistics.median(skews) / 1e6,
        "skew_max_ms": max(skews) / 1e6,
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("-n", type=int, default=1000, help="tuples per rate (default 1000)")
    p.add_argument("--rates", type=float, nargs="+", default=[5.0, 12.5], help="stream rates, Hz (default 5 12.5)")
    p.add_argument("--fps", type=float, default=25.0, help="camera frame rate (default 25)")
    p.add_argument("--phase-ms", type=float, default=13.0, help="the second camera's phase (default 13)")
    args = p.parse_args(argv)
    if args.n < 2 or args.fps <= 0 or any(r <= 0 for r in args.rates):
        p.error("-n must be >= 2, --fps and --rates positive")
    small = "width=64,height=48"
    period_ns = round(1e9 / args.fps)
    ok = True
    try:
        with Lab() as lab:
            a, b = lab.host(clock_offset_s=1000), lab.host(clock_offset_s=3000)
            sa = a.service("--camera", f"left=synthetic:fps={args.fps},{small}")
            sb = b.service("--camera", f"right=synthetic:fps={args.fps},phase_ms={args.phase_ms},{small}")
            offsets = {sa.endpoint: a.clock_offset_ns, sb.endpoint: b.clock_offset_ns}
            with Client([sa.endpoint, sb.endpoint], timeout=15, keys=lab.client_keys) as client:
                print(
                    f"{'rate Hz':>8} {'tuples':>7} {'got Hz':>8} {'sched Hz':>9} {'lost':>5} {'failed':>7} "
                    f"{'spikes':>7} {'skew med ms':>12} {'skew max ms':>12}"
                )
                for rate in args.rates:
                    r = run_rate(client, offsets, rate, args.n, period_ns)
                    print(
                        f"{r['rate_hz']:>8} {r['tuples']:>7} {r['delivered_hz']:>8.3f} {r['scheduled_hz']:>9.3f} "
                        f"{r['lost']:>5} {r['failed']:>7} {r['spikes']:>7} {r['skew_median_ms']:>12.3f} "
                        f"{r['skew_max_ms']:>12.3f}",
                        flush=True,
                    )
                    ok &= r["spikes"] == 0 and r["failed"] == 0 and r["lost"] == 0
                    ok &= abs(r["delivered_hz"] - rate) <= 0.01 * rate
    except HostsUnavailable as exc:
        print(f"cannot make emulated hosts: {exc}", file=sys.stderr)
        return 2
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
