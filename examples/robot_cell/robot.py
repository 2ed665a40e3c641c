"""The robot control node of the robotic cell (the paper's Fig. 1).

At random moments (sleeps drawn from U[a, b]) the robot "needs" a stereo pair:
it publishes a request event ``{"op": "tuple", "at": now, "reply_topic":
"cell/pairs"}`` to the acquisition service. The service answers with the pair
of images closest to ``at`` on ``cell/pairs``; the vision node turns the pair
into a disparity and publishes it on ``cell/results``, where the robot waits
for it. For each result the robot prints the end-to-end latency (arrival of
the result minus the moment the event was published) and the disparity; at the
end, a summary.

    python robot.py --events tcp://127.0.0.1:5557 --pub tcp://127.0.0.1:5556 \\
                    --results tcp://127.0.0.1:5558 -n 20

Before the first request it checks both legs it depends on, each with a
deadline: its events reach the service (``fxis_shm.client.pubsub.handshake`` on a
topic of its own, hence ``--pub``), and a ``time`` event on ``cell/pairs``
comes back through the vision node as a ping on ``cell/results``.
Times are ns of CLOCK_MONOTONIC: the robot runs on the service's host.
"""

from __future__ import annotations

import argparse
import json
import random
import sys
import time
from dataclasses import dataclass

import numpy as np
import zmq

from fxis_shm import EventPublisher, RequestTimeout, Subscriber, handshake

PAIRS_TOPIC = "cell/pairs"  # where the service answers our events, and the vision node listens
RESULTS_TOPIC = "cell/results"  # what the vision node publishes
PROBE_TOPIC = "cell/robot-probe"  # answers to our handshake probes only
DEFAULT_RESULTS = "tcp://127.0.0.1:5558"


@dataclass
class Outcome:
    request_id: int
    t_published: int  # ns; also the request's t* ("at")
    t_arrived: int | None = None  # None: no result within the timeout
    result: dict | None = None

    @property
    def ok(self) -> bool:
        return self.result is not None and "error" not in self.result

    @property
    def latency_ms(self) -> float | None:
        return None if self.t_arrived is None else (self.t_arrived - self.t_published) / 1e6


class ResultFeed:
    """The vision node's results: a SUB socket on ``cell/results``."""

    def __init__(self, endpoint: str, ctx: zmq.Context):
        self.endpoint = endpoint
        self._sock = ctx.socket(zmq.SUB)
        self._sock.setsockopt(zmq.LINGER, 0)
        self._sock.setsockopt(zmq.SUBSCRIBE, RESULTS_TOPIC.encode())
        self._sock.connect(endpoint)

    def receive(self, until_ns: int) -> tuple[dict, int] | None:
        """The next result and its arrival time, or None if none came before ``until_ns``."""
        while True:
            left_ms = (until_ns - time.monotonic_ns()) / 1e6
            if left_ms <= 0 or not self._sock.poll(left_ms, zmq.POLLIN):
                return None
            frames = self._sock.recv_multipart()
            t_arrived = time.monotonic_ns()
            if len(frames) != 2 or frames[0] != RESULTS_TOPIC.encode():
                continue  # a longer topic that merely starts with ours
            try:
                result = json.loads(frames[1])
            except ValueError:
                print(f"robot: skipped a result that is not JSON: {frames[1][:80]!r}", file=sys.stderr)
                continue
            if isinstance(result, dict):
                return result, t_arrived

    def close(self) -> None:
        self._sock.close()


def check_chain(events: EventPublisher, pub: str, feed: ResultFeed, timeout: float, ctx: zmq.Context) -> None:
    """Return once events reach the service and vision results reach us; raise RequestTimeout if not."""
    with Subscriber(pub, context=ctx) as probe:
        probe.topic(PROBE_TOPIC)
        handshake(events, probe, PROBE_TOPIC, timeout=timeout)
    deadline = time.monotonic_ns() + int(timeout * 1e9)
    while time.monotonic_ns() < deadline:
        ping = events.request("time", PAIRS_TOPIC)
        retry = min(deadline, time.monotonic_ns() + 250_000_000)
        while (got := feed.receive(retry)) is not None:
            if got[0].get("ping") and got[0].get("request_id") == ping:
                return
    raise RequestTimeout(
        f"no ping came back on {RESULTS_TOPIC!r} from {feed.endpoint} within "
        f"{timeout} s: is the vision node running and subscribed to {pub}?"
    )


def run(
    events_endpoint: str,
    pub: str,
    results: str,
    n: int,
    sleep=(0.13, 0.23),
    timeout: float = 10.0,
    cameras=("left", "right"),
    seed: int | None = None,
    ready_timeout: float = 10.0,
    out=print,
) -> list[Outcome]:
    """Publish ``n`` requests at random moments; return what became of each."""
    rng = random.Random(seed)
    ctx = zmq.Context()
    outcomes: list[Outcome] = []
    try:
        with EventPublisher(events_endpoint, context=ctx) as events:
            feed = ResultFeed(results, ctx)
            try:
                check_chain(events, pub, feed, ready_timeout, ctx)
                pending: dict[int, Outcome] = {}
                next_at = time.monotonic_ns() + int(rng.uniform(*sleep) * 1e9)
                while len(outcomes) < n or pending:
                    now = time.monotonic_ns()
                    if len(outcomes) < n and now >= next_at:
                        t = time.monotonic_ns()  # the moment the robot needs the images
                        rid = events.request("tuple", PAIRS_TOPIC, at=t, cameras=list(cameras))
                        pending[rid] = Outcome(rid, t)
                        outcomes.append(pending[rid])
                        next_at = t + int(rng.uniform(*sleep) * 1e9)
                        continue
                    for rid, o in list(pending.items()):
                        if now - o.t_published > timeout * 1e9:
                            del pending[rid]
                            out(f"result  {outcomes.index(o) + 1:2d}/{n}  request {rid}: no result within {timeout} s")
                    wake = min(
                        [o.t_published + int(timeout * 1e9) for o in pending.values()]
                        + ([next_at] if len(outcomes) < n else []),
                        default=now,
                    )
                    got = feed.receive(wake)
                    if got is None:
                        continue
                    result, t_arrived = got
                    o = pending.pop(result.get("request_id"), None)
                    if o is None:
                        continue  # a late ping, or a result for someone else
                    o.t_arrived, o.result = t_arrived, result
                    out(describe(outcomes.index(o) + 1, n, o))
            finally:
                feed.close()
    finally:
        ctx.term()
    return outcomes


def describe(i: int, n: int, o: Outcome) -> str:
    head = f"result  {i:2d}/{n}  request {o.request_id}: latency {o.latency_ms:7.1f} ms"
    r = o.result
    if "error" in r:
        return f"{head}  ERROR {r['error']}"
    frames = " ".join(f"{c}={f}" for c, f in r["frames"].items())
    parts = (
        f"pair after {(r['t_received'] - o.t_published) / 1e6:.1f}, "
        f"vision {(r['t_done'] - r['t_received']) / 1e6:.1f}, "
        f"back {(o.t_arrived - r['t_done']) / 1e6:.1f} ms"
    )
    return f"{head}  disparity {r['disparity_px']:7.3f} px  frames {frames}  ({parts})"


def summary(outcomes: list[Outcome]) -> list[str]:
    answered = [o for o in outcomes if o.ok]
    failed = [o for o in outcomes if o.result is not None and not o.ok]
    lost = [o for o in outcomes if o.result is None]
    lines = [
        f"requests: {len(outcomes)} published, {len(answered)} answered, "
        f"{len(failed)} errors, {len(lost)} without a result"
    ]
    if answered:
        lat = np.array([o.latency_ms for o in answered])
        lines.append(
            f"latency: n {len(lat)}, median {np.median(lat):.1f} ms, "
            f"p90 {np.percentile(lat, 90):.1f} ms, max {lat.max():.1f} ms"
        )
        disp = np.array([o.result["disparity_px"] for o in answered])
        lines.append(f"disparity: mean {disp.mean():.3f} px, min {disp.min():.3f}, max {disp.max():.3f}")
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--events", default="tcp://127.0.0.1:5557", help="the service's events endpoint")
    p.add_argument(
        "--pub", default="tcp://127.0.0.1:5556", help="the service's publish endpoint (only for the start-up handshake)"
    )
    p.add_argument("--results", default=DEFAULT_RESULTS, help="the vision node's results endpoint")
    p.add_argument("-n", type=int, default=20, help="number of requests (default 20)")
    p.add_argument(
        "--sleep",
        type=float,
        nargs=2,
        default=(0.13, 0.23),
        metavar=("A", "B"),
        help="seconds between requests, uniform in [A, B] (default 0.13 0.23)",
    )
    p.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for each result (default 10)")
    p.add_argument("--cameras", default="left,right", help="the stereo pair's cameras")
    p.add_argument("--seed", type=int, help="seed of the random sleeps")
    args = p.parse_args(argv)
    try:
        outcomes = run(
            args.events,
            args.pub,
            args.results,
            args.n,
            tuple(args.sleep),
            args.timeout,
            args.cameras.split(","),
            args.seed,
        )
    except RequestTimeout as exc:
        print(f"robot: {exc}", file=sys.stderr)
        return 1
    for line in summary(outcomes):
        print(line)
    return 0 if all(o.ok for o in outcomes) else 1


if __name__ == "__main__":
    sys.exit(main())
