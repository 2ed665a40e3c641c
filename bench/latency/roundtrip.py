"""Request latency of a working service: what a request costs apart from waiting for frames.

Launches the default service (synthetic cameras cam0, cam1 at 20 fps, 1360x1024 mono8, rings
of 20 slots, over tcp loopback) unless --endpoint is given, then measures N round trips of
each of three requests, interleaved in random order, each after a random sleep U[0, 50] ms
so that the requests fall on every phase of the frame period:

  tuple        client.tuple() of every camera with the service defaults (sync=joint, wait=auto).
               Reported as the client's round trip MINUS the time the service waited for frames
               (timing.waited - timing.received), as the raw round trip, and split into the
               service's steps: received->waited (the wait), waited->searched, searched->copied,
               copied->sent, plus the two transits client send->received and sent->client got
               the reply (the bench and the service share CLOCK_MONOTONIC on one host).
  tuple none   client.tuple(wait="none"): answered from what is stored, raw round trip.
  latest       client.latest(): the newest frame of every camera, raw round trip.

Prints median, p99, mean, min and max (ms) per row; writes request_latency.json (every raw
sample, timing record and frame) and request_latency.png (a CDF per row) into --out.
Exit status: 0 if every request was answered, 1 if any failed (the outputs are still
written), 2 on bad flags.
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import time

if not __package__:  # run as a script (python bench/latency/roundtrip.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common

KINDS = ("tuple", "tuple_none", "latest")
LABELS = {"tuple": "tuple (wait=auto)", "tuple_none": "tuple (wait=none)", "latest": "latest"}
SERVICE_STEPS = (("received", "waited"), ("waited", "searched"), ("searched", "copied"), ("copied", "sent"))


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    common.add_pacing_args(p, "of each kind", count=300, warmup=5, sleep_max_ms=50.0)
    cams = p.add_argument_group("the launched service (ignored with --endpoint)")
    cams.add_argument("--cameras", type=common.positive_int, default=2, help="synthetic cameras cam0, cam1, ...")
    cams.add_argument("--fps", type=common.positive_float, default=20.0)
    common.add_frame_size_args(cams, 1360, 1024)
    cams.add_argument("--slots", type=common.positive_int, default=20, help="frames per camera ring")
    common.add_service_args(p, "every camera of that service is requested")
    return p


def _request(client, kind: str):
    if kind == "tuple":
        return client.tuple()
    if kind == "tuple_none":
        return client.tuple(wait="none")
    return client.latest()


def measure(client, kind: str, kinds_of: dict) -> dict:
    """One request of ``kind``: client times, the service's timing record, the frames."""
    rec = {"kind": kind, "error": None}
    t_send = time.monotonic_ns()
    try:
        reply = _request(client, kind)
    except common.REQUEST_ERRORS as exc:
        rec.update(t_send=t_send, t_reply=time.monotonic_ns(), error=common.describe_error(exc))
        return rec
    t_reply = time.monotonic_ns()
    rec.update(
        t_send=t_send,
        t_reply=t_reply,
        rtt_ns=t_reply - t_send,
        t_request=reply.t_request,
        timing=reply.timing,
        frames={
            cam: {
                "frame_id": f.frame_id,
                "t_capture": f.t_capture,
                "t_stored": f.t_stored,
                "stamp_ok": common.stamp_ok(f, kinds_of.get(cam, "")),
            }
            for cam, f in reply.items()
        },
    )
    return rec


def rows_of(records: list[dict]) -> list[tuple[str, list[float]]]:
    """(label, samples in ms) per table row, in print order."""
    ok = {k: [r for r in records if r["kind"] == k and r["error"] is None] for k in KINDS}
    tup = ok["tuple"]

    def wait_ns(r):
        return r["timing"]["waited"] - r["timing"]["received"]

    rows = [
        ("tuple (wait=auto): round trip - wait", [common.ms(r["rtt_ns"] - wait_ns(r)) for r in tup]),
        ("tuple (wait=auto): round trip", [common.ms(r["rtt_ns"]) for r in tup]),
    ]
    for a, b in SERVICE_STEPS:
        label = f"  service {a}->{b}" + ("  (the wait)" if a == "received" else "")
        rows.append((label, [common.ms(r["timing"][b] - r["timing"][a]) for r in tup]))
    rows += [
        ("  client send->service received", [common.ms(r["timing"]["received"] - r["t_send"]) for r in tup]),
        ("  service sent->client has reply", [common.ms(r["t_reply"] - r["timing"]["sent"]) for r in tup]),
        ("tuple (wait=none): round trip", [common.ms(r["rtt_ns"]) for r in ok["tuple_none"]]),
        ("latest: round trip", [common.ms(r["rtt_ns"]) for r in ok["latest"]]),
    ]
    return rows


def plot(rows: list[tuple[str, list[float]]], path: str, title: str) -> None:
    plt = common.pyplot()
    import numpy as np
    from matplotlib import ticker

    fig, axes = plt.subplots(1, 2, figsize=(13, 5), sharey=True)
    client_rows = [r for r in rows if not r[0].startswith("  ")]
    detail_rows = [r for r in rows if r[0].startswith("  ")]
    for ax, group, heading in (
        (axes[0], client_rows, "client round trips"),
        (axes[1], detail_rows, "tuple (wait=auto): steps"),
    ):
        for label, values in group:
            if not values:
                continue
            x = np.sort(np.asarray(values))
            y = np.arange(1, x.size + 1) / x.size
            ax.step(np.maximum(x, 1e-3), y, where="post", label=f"{label.strip()} (median {np.median(x):.2f} ms)")
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
        ax.set_xlabel("ms (log scale; 0 is drawn at 0.001)")
        ax.set_title(heading)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8, loc="best")
    axes[0].set_ylabel("fraction of requests (CDF)")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(args, client, status: dict) -> list[dict]:
    rng = random.Random(args.seed)
    kinds_of = {cam: c["kind"] for cam, c in status["cameras"].items()}
    for _ in range(args.warmup):
        for kind in KINDS:
            measure(client, kind, kinds_of)
    schedule = [kind for _ in range(args.requests) for kind in rng.sample(KINDS, len(KINDS))]
    records = []
    with common.progress(len(schedule), "request_latency") as bar:
        for i, kind in enumerate(schedule):
            sleep = rng.uniform(0.0, args.sleep_max_ms)
            common.sleep_ms(sleep)
            rec = measure(client, kind, kinds_of)
            rec.update(i=i, sleep_ms=sleep)
            records.append(rec)
            bar.update(1)
    return records


def main(argv: list[str] | None = None) -> int:
    parsed = common.parse_args_and_out(parser(), argv)
    if isinstance(parsed, int):
        return parsed
    args, out = parsed
    names = [f"cam{j}" for j in range(args.cameras)]
    run_args = common.synthetic_camera_flags(names, args.fps, args.width, args.height)
    run_args += ["--slots", str(args.slots)]
    started = time.time()
    host = common.host_info()  # before the service starts: the code it runs
    try:
        with common.service(
            args.endpoint, run_args, os.path.join(out, "request_latency.service.log"), args.timeout
        ) as (client, info):
            status = common.wait_until_streaming(client)
            records = run(args, client, status)
            status_after = client.status()
    except RuntimeError as exc:
        print(f"request_latency: {exc}", file=sys.stderr)
        return common.EXIT_FAILED

    rows = rows_of(records)
    failed = [r for r in records if r["error"] is not None]
    bad_stamps = sum(1 for r in records for f in r.get("frames", {}).values() if f["stamp_ok"] is False)
    tup = [r for r in records if r["kind"] == "tuple" and r["error"] is None]
    waited = sum(1 for r in tup if r["timing"]["waited"] - r["timing"]["received"] > 1_000_000)
    cams = status["cameras"]
    first = next(iter(cams.values()))
    shape = "x".join(map(str, first.get("shape", [])[1::-1]))  # width x height
    title = (
        f"request latency: {len(cams)} cameras {shape} {first.get('dtype')} at "
        f"{first.get('fps')} fps, "
        f"{info['endpoint']}, {args.requests} requests per kind"
    )

    summaries = {label.strip(): common.summary(values) for label, values in rows}
    print(common.code_line(host["code"]))
    print(title)
    print(
        common.table(
            ["row (ms)", "n", "median", "p99", "mean", "min", "max"],
            [
                [label, s["n"], s["median"], s["p99"], s["mean"], s["min"], s["max"]]
                for (label, _), s in zip(rows, summaries.values())
            ],
            digits=3,
        )
    )
    print(
        f"tuple (wait=auto) waited > 1 ms for a frame in {waited} of {len(tup)} requests; "
        f"failed requests: {len(failed)}; frames whose pixel stamp did not match their id: {bad_stamps}"
    )
    for r in failed[:10]:
        print(f"  failed: request {r['i']} ({r['kind']}): {r['error']}")

    json_path = os.path.join(out, "request_latency.json")
    png_path = os.path.join(out, "request_latency.png")
    common.write_json(
        json_path,
        {
            **common.run_record("request_latency", started, argv, args),
            "service": info,
            "host": host,
            "status_before": status,
            "status_after": status_after,
            "clock": "CLOCK_MONOTONIC ns; t_send/t_reply are the bench's time.monotonic_ns()",
            "summary_ms": summaries,
            "failed": len(failed),
            "stamp_mismatches": bad_stamps,
            "records": records,
        },
    )
    plot(rows, png_path, title)
    print(f"wrote {json_path} and {png_path}")
    return common.EXIT_FAILED if failed else common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
