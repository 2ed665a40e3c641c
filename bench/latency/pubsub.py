"""Publish/subscribe: the paper's event-driven path (its Fig. 1) and tuple streams.

Launches the default service (synthetic cameras cam0, cam1 at 20 fps, 1360x1024 mono8)
unless --endpoint is given, then measures:

  events   N request events ("tuple", t* = the moment the event arrives), each after a random
           sleep U[0, 50] ms, published on the events endpoint; the answer is received by a
           subscriber of the reply topic. Reported: publish -> answer received (raw), the same
           minus the service's wait for frames (timing.waited - timing.received), and the
           transit service sent -> subscriber has it.
  streams  for --seconds, 4 subscribers of the tuple stream "tuples|", one of them stalled
           (it never reads; queue of 2), while a client requests a tuple every 50 ms. Reported:
           tuples per second each live subscriber received, its lost messages (seq gaps), and
           the request latency meanwhile; the stalled subscriber's backlog afterwards.

Prints tables; writes pubsub.json and pubsub.png into --out. Exit status 0 if every event
was answered and every request served, 1 otherwise, 2 on bad flags.
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import threading
import time

if not __package__:  # run as a script (python bench/latency/pubsub.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common
from fxis_shm import FxisError, RequestTimeout
from fxis_shm.client.pubsub import EventPublisher, Subscriber, handshake

REPLY_TOPIC = "bench/pairs"
LIVE_SUBSCRIBERS = 3


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    p.add_argument("-n", "--events", type=common.positive_int, default=200, help="request events to measure")
    p.add_argument("--seconds", type=common.positive_float, default=10.0, help="how long the stream part runs")
    cams = p.add_argument_group("the launched service (ignored with --endpoint)")
    cams.add_argument("--fps", type=common.positive_float, default=20.0)
    common.add_frame_size_args(cams, 1360, 1024)
    common.add_service_args(p)
    return p


def measure_events(info: dict, n: int, rng: random.Random, timeout: float) -> dict:
    records, failures = [], 0
    with EventPublisher(info["events"]) as events, Subscriber(info["pub"], timeout=timeout) as answers:
        answers.topic(REPLY_TOPIC)
        handshake(events, answers, REPLY_TOPIC)
        bar = common.progress(n, "events")
        for _ in range(n):
            common.sleep_ms(rng.uniform(0, 50))
            t0 = time.monotonic_ns()
            rid = events.request("tuple", REPLY_TOPIC)
            try:
                message = answers.receive()
                while message.header.get("id") != rid:  # a late answer to a handshake probe
                    message = answers.receive()
                t1 = time.monotonic_ns()
                pair = message.tuple
            except FxisError as exc:
                failures += 1
                print(f"event failed: {common.describe_error(exc)}", file=sys.stderr)
                continue
            timing = pair.timing
            records.append(
                {
                    "t_publish": t0,
                    "t_received": t1,
                    "timing": timing,
                    "skew_ns": pair.skew_ns,
                    "frames": {c: f.frame_id for c, f in pair.items()},
                }
            )
            bar.update()
        bar.close()
    return {"records": records, "failures": failures}


def measure_streams(info: dict, client, seconds: float, timeout: float) -> dict:
    stop = threading.Event()
    live = [{"seqs": [], "frames": []} for _ in range(LIVE_SUBSCRIBERS)]
    requests = {"latency_ms": [], "failures": 0}
    subscribers = [Subscriber(info["pub"], timeout=timeout) for _ in live]
    stalled = Subscriber(info["pub"], timeout=1.0, queue=2)
    threads = []
    try:
        for sub in (*subscribers, stalled):
            sub.tuples()
        stalled.receive(timeout=timeout)  # connected; from now on it does not read

        def listen(sub, record):
            while not stop.is_set():
                try:
                    message = sub.receive(timeout=0.2)
                except RequestTimeout:
                    continue
                record["seqs"].append(message.seq)
                record["frames"].append(message.header["frames"][0]["frame_id"])

        def request():
            while not stop.is_set():
                t0 = time.monotonic_ns()
                try:
                    client.tuple()
                    requests["latency_ms"].append(common.ms(time.monotonic_ns() - t0))
                except FxisError:
                    requests["failures"] += 1
                stop.wait(0.05)

        for sub, record in zip(subscribers, live):
            threads.append(threading.Thread(target=listen, args=(sub, record)))
        threads.append(threading.Thread(target=request))
        for t in threads:
            t.start()
        stop.wait(seconds)
        stop.set()
        for t in threads:
            t.join(timeout + 1)
        # The stalled subscriber's backlog: what it had queued when the run stopped
        # (the stream goes on, so read up to the last message the live ones saw).
        last = max((r["seqs"][-1] for r in live if r["seqs"]), default=0)
        backlog = []
        while not backlog or backlog[-1] < last:
            try:
                backlog.append(stalled.receive(timeout=1.0).seq)
            except RequestTimeout:
                break
    finally:
        stop.set()
        for sub in (*subscribers, stalled):
            sub.close()
    return {"seconds": seconds, "live": live, "requests": requests, "stalled_backlog": backlog}


def lost(seqs: list[int]) -> int:
    return sum(b - a - 1 for a, b in zip(seqs, seqs[1:]))


def report(events: dict, streams: dict, fps: float | None) -> tuple[str, dict]:
    recs = events["records"]
    raw = [common.ms(r["t_received"] - r["t_publish"]) for r in recs]
    waits = [common.ms(r["timing"]["waited"] - r["timing"]["received"]) for r in recs]
    transit = [common.ms(r["t_received"] - r["timing"]["sent"]) for r in recs]
    rows = {
        "event -> tuple at subscriber": common.summary(raw),
        "  the same minus the wait for frames": common.summary(a - w for a, w in zip(raw, waits)),
        "  service sent -> subscriber has it": common.summary(transit),
        "  the wait for frames": common.summary(waits),
    }
    header = ["events (ms)", "n", "median", "p99", "mean", "min", "max"]
    text = [
        common.table(
            header, [[k, v["n"], v["median"], v["p99"], v["mean"], v["min"], v["max"]] for k, v in rows.items()]
        )
    ]
    stream_rows = []
    for i, rec in enumerate(streams["live"]):
        rate = len(rec["seqs"]) / streams["seconds"]
        stream_rows.append([f"live subscriber {i + 1}", len(rec["seqs"]), rate, lost(rec["seqs"])])
    backlog = streams["stalled_backlog"]
    stream_rows.append(["stalled subscriber (backlog read after)", len(backlog), "-", lost(backlog)])
    text.append(
        common.table(
            ["tuple stream, 4 subscribers", "messages", "per s", "lost (seq gaps)"],
            stream_rows,
            title=f"\ncamera rate {fps or '?'} fps, over {streams['seconds']:g} s",
        )
    )
    req = common.summary(streams["requests"]["latency_ms"])
    text.append(
        f"tuple requests meanwhile: {req['n']} served, {streams['requests']['failures']} failed, "
        f"median {common.fmt(req['median'])} ms, p99 {common.fmt(req['p99'])} ms"
    )
    return "\n".join(text), {"events": rows, "streams": stream_rows, "requests": req}


def plot(path: str, events: dict, streams: dict) -> None:
    plt = common.pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
    raw = sorted(common.ms(r["t_received"] - r["t_publish"]) for r in events["records"])
    left.plot(raw, [(i + 1) / len(raw) for i in range(len(raw))])
    left.set(xlabel="request event -> tuple received (ms)", ylabel="fraction", title="event latency (CDF)")
    for i, rec in enumerate(streams["live"]):
        t = range(len(rec["frames"]))
        right.plot(t, rec["frames"], label=f"live {i + 1}")
    right.set(xlabel="message", ylabel="frame id", title="tuple stream at live subscribers")
    right.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = common.parse_args(p, argv)
    if isinstance(args, int):
        return args
    seed = args.seed
    rng = random.Random(seed)
    out = common.ensure_dir(args.out)
    run_args = common.synthetic_camera_flags(["cam0", "cam1"], args.fps, args.width, args.height)
    with common.service(args.endpoint, run_args, os.path.join(out, "pubsub.service.log"), args.timeout) as (
        client,
        info,
    ):
        status = common.wait_until_streaming(client)
        fps = next(iter(status["cameras"].values())).get("fps")
        events = measure_events(info, args.events, rng, args.timeout)
        streams = measure_streams(info, client, args.seconds, args.timeout)
    text, summary = report(events, streams, fps)
    print(f"pubsub: {common.code_line(common.code_version())}; seed {seed}")
    print(text)
    common.write_json(
        os.path.join(out, "pubsub.json"),
        {
            "seed": seed,
            "info": info,
            "summary": summary,
            "events": events,
            "streams": streams,
            "code": common.code_version(),
        },
    )
    plot(os.path.join(out, "pubsub.png"), events, streams)
    failed = events["failures"] or streams["requests"]["failures"]
    return common.EXIT_FAILED if failed else common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
