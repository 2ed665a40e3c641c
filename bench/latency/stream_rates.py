"""Stream rates: does a decimated stream deliver the rate it was asked for, over seconds?

Launches a service with one small synthetic camera per --fps value (cam15 at 15 fps, ...),
subscribes to every camera's frame stream at every --rates value, and to the tuple stream
(of all the cameras: as fast as the slowest) at every rate, for --seconds. Counts the messages of each stream by
their capture times (the first message starts the clock) and prints, per stream, the rate
asked, the rate the camera allows (min of the two), the rate delivered and the gap between
consecutive messages (median, min, max, in camera periods).

Writes stream_rates.json into --out. Exit status 0 if every stream delivered its rate within
one message over the run, 1 otherwise, 2 on bad flags.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import threading
import time

if not __package__:  # run as a script (python bench/latency/stream_rates.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common
from fxis_shm import RequestTimeout
from fxis_shm.client.pubsub import Subscriber


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    p.add_argument(
        "--fps", type=common.positive_float, nargs="+", default=[15, 20, 25, 30, 100], help="one camera per frame rate"
    )
    p.add_argument(
        "--rates",
        type=common.positive_float,
        nargs="+",
        default=[1, 7, 10, 12.5, 30],
        help="stream rates to ask for, Hz",
    )
    p.add_argument("--seconds", type=common.positive_float, default=10.0, help="how long each stream is counted")
    common.add_output_args(p)
    return p


def measure(pub: str, topics: list[str], seconds: float, timeout: float) -> dict[str, list[int]]:
    """Capture times of every message of each topic, over ``seconds`` from its first message.
    Each stream has a subscriber (a connection) of its own, as separate viewers would: the
    service's bounded queue is per connection, and one connection reading every stream at
    once would lose messages of some when others come in bursts."""
    times: dict[str, list[int]] = {t: [] for t in topics}
    end = time.monotonic() + seconds + 3.0  # every stream has started by then

    def count(topic: str) -> None:
        with Subscriber(pub, timeout=timeout, queue=10_000) as sub:
            sub.topic(topic)
            while time.monotonic() < end:
                try:
                    message = sub.receive(timeout=0.5)
                except RequestTimeout:
                    continue
                times[topic].append(max(f.t_capture for f in message.frames))

    threads = [threading.Thread(target=count, args=(topic,), daemon=True) for topic in topics]
    for thread in threads:
        thread.start()
    bar = common.progress(int(seconds + 3), "streams")
    while time.monotonic() < end:
        time.sleep(1.0)
        bar.update()
    bar.close()
    for thread in threads:
        thread.join(timeout + 1.0)
    return {t: [x for x in ts if ts and x - ts[0] < seconds * 1e9] for t, ts in times.items()}


def main(argv: list[str] | None = None) -> int:
    parsed = common.parse_args_and_out(parser(), argv)
    if isinstance(parsed, int):
        return parsed
    args, out = parsed
    names = {f"cam{fps:g}".replace(".", "_"): fps for fps in args.fps}
    run_args = [flag for name, fps in names.items() for flag in common.synthetic_camera_flags([name], fps, 64, 48)]
    streams = {}  # topic -> (label, asked rate, camera-limited rate, period ns)
    for name, fps in names.items():
        for rate in args.rates:
            streams[f"frames/{name}@{rate:g}|"] = (f"frames {fps:g} fps", rate, min(rate, fps), 1e9 / fps)
    slowest = min(names.values())
    for rate in args.rates:
        streams[f"tuples@{rate:g}|"] = (f"tuples of {len(names)} cameras", rate, min(rate, slowest), 1e9 / slowest)
    with common.service(None, run_args, os.path.join(out, "stream_rates.service.log"), args.timeout) as (client, info):
        common.wait_until_streaming(client)
        times = measure(info["pub"], list(streams), args.seconds, args.timeout)
    rows, ok, results = [], True, {}
    for topic, (label, rate, allowed, period) in streams.items():
        ts = times[topic]
        gaps = [(b - a) / period for a, b in zip(ts, ts[1:])]
        delivered = len(ts) / args.seconds
        good = abs(len(ts) - allowed * args.seconds) <= 1
        ok &= good
        results[topic] = {"asked_hz": rate, "allowed_hz": allowed, "messages": len(ts), "delivered_hz": delivered}
        rows.append(
            [
                label,
                f"{rate:g}",
                f"{allowed:g}",
                f"{delivered:.2f}",
                *(f"{f(gaps):.2f}" if gaps else "-" for f in (statistics.median, min, max)),
                "ok" if good else "OFF",
            ]
        )
    print(f"stream_rates: {common.code_line(common.code_version())}; {args.seconds:g} s per stream")
    print(
        common.table(
            ["stream", "asked Hz", "allowed Hz", "delivered Hz", "gap med", "gap min", "gap max", ""],
            rows,
            title="gaps in camera periods",
        )
    )
    common.write_json(os.path.join(out, "stream_rates.json"), {"results": results, "code": common.code_version()})
    return common.EXIT_OK if ok else common.EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())
