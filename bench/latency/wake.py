"""Waiting on the local path: how soon after a frame is stored the same-host client returns it.

The local client (Client(local="require")) answers from the rings itself: when a request must
wait for a frame, it sleeps until just before the frame is due, then watches the ring's write
counter. Measured here, per request that had to wait: from the moment the frame it waited
for was stored (t_stored, the service's CLOCK_MONOTONIC, which is this process's on one host)
to the moment the call returned (time.monotonic_ns() right after it). For "next" that is the
last camera's first frame stored after the request was made (read from the rings' frame
times after the call: the paper's policy then chooses the frame nearest to t*, which may be
the one before); for "future", the last returned frame stored after the request. A request
that found every frame it needed already stored did not wait and is left out; the table says
how many waited.

Requests, --wake-requests of each kind, interleaved, each after a random sleep U[0, tau_ia]
so that they fall at every phase of the frame period:
  next      tuple(sync="independent", wait="next"): the next frame of every camera;
  future    tuple(at=now + U[0.2, 0.8] tau_ia): t* slightly in the future, the service's
            default wait (wait until the nearest frame to t* is known);
each copied (the default) and zero-copy (copy=False: views, no copy), so the copy's share
shows. Targets, on every request that waited, copied and zero-copy apart: median <= 0.5 ms,
p99 <= 2 ms.
"""

from __future__ import annotations

import random
import time

from bench.shared import common

MEDIAN_LIMIT_MS, P99_LIMIT_MS = 0.5, 2.0
KINDS = ("next", "future")
COPIES = {"copied": True, "zero-copy": False}


def request(client, kind: str, copy: bool, names: list[str], period_ns: int, rng: random.Random):
    if kind == "next":
        return client.tuple(names, sync="independent", wait="next", copy=copy)
    return client.tuple(names, at=time.monotonic_ns() + int(rng.uniform(0.2, 0.8) * period_ns), copy=copy)


def measure(client, kind: str, copy_name: str, names: list[str], period_ns: int, rng: random.Random) -> dict:
    """One request: when it was made and returned, and its frames' storage times."""
    rec = {"kind": kind, "copy": copy_name, "error": None}
    t_send = time.monotonic_ns()
    try:
        reply = request(client, kind, COPIES[copy_name], names, period_ns, rng)
    except common.REQUEST_ERRORS as exc:
        rec.update(t_send=t_send, error=common.describe_error(exc))
        return rec
    t_return = time.monotonic_ns()
    stored = {cam: reply[cam].t_stored for cam in names}
    reply.release()
    if kind == "next":  # what it waited for: each camera's first frame after the request
        stored = first_stored_after(client.frame_times(names), names, t_send)
    rec.update(
        t_send=t_send,
        t_return=t_return,
        t_stored=stored,
        came_by=reply.path,
        **wake_of(t_send, t_return, stored.values()),
    )
    return rec


def first_stored_after(listing: dict, names: list[str], t_send: int) -> dict:
    """Each camera's first storage time after ``t_send``, from a ``frames`` reply."""
    column = listing["columns"].index("t_stored")
    return {
        cam: min((row[column] for row in listing["cameras"][cam]["frames"] if row[column] > t_send), default=t_send)
        for cam in names
    }


def wake_of(t_send: int, t_return: int, t_stored) -> dict:
    """Whether a request waited (a frame it returns was stored after it was made) and, if so,
    the ms from the last such frame's storage to the return."""
    after = [t for t in t_stored if t > t_send]
    return {"waited": bool(after), "wake_ms": common.ms(t_return - max(after)) if after else None}


def run(args, client, names: list[str], period_ns: int) -> list[dict]:
    rng = random.Random(args.seed + 1)
    plan = [(kind, c) for kind in KINDS for c in COPIES] * args.wake_requests
    rng.shuffle(plan)
    records = []
    with common.progress(len(plan), "latency, local waits") as bar:
        for kind, copy_name in plan:
            common.sleep_ms(rng.uniform(0.0, period_ns / 1e6))
            records.append(measure(client, kind, copy_name, names, period_ns, rng))
            bar.update(1)
    return records


def summarize(records: list[dict]) -> dict:
    """Per kind and copy, and per copy over both kinds: how many waited, wake-up ms summary."""

    def group(recs):
        ok = [r for r in recs if r["error"] is None]
        return {
            "requests": len(recs),
            "failed": len(recs) - len(ok),
            "not_local": sum(r["came_by"] != "local" for r in ok),
            "waited": sum(r["waited"] for r in ok),
            "wake_ms": common.summary(r["wake_ms"] for r in ok if r["waited"]),
        }

    out = {
        f"{kind}, {c}": group([r for r in records if r["kind"] == kind and r["copy"] == c])
        for kind in KINDS
        for c in COPIES
    }
    out.update({f"all, {c}": group([r for r in records if r["copy"] == c]) for c in COPIES})
    return out


def targets(summary: dict) -> list[dict]:
    out = []
    for c in COPIES:
        s = summary[f"all, {c}"]["wake_ms"]
        for stat, limit in (("median", MEDIAN_LIMIT_MS), ("p99", P99_LIMIT_MS)):
            value = s[stat]
            out.append(
                {
                    "target": f"local wake-up {stat}, {c}",
                    "value_ms": value,
                    "limit_ms": limit,
                    "ratio": None if value is None else value / limit,
                    "passed": None if value is None else value <= limit,
                }
            )
    return out


def report(summary: dict, tlist: list[dict]) -> str:
    rows = [
        [
            name,
            g["requests"],
            g["failed"],
            g["waited"],
            g["wake_ms"]["median"],
            g["wake_ms"]["p99"],
            g["wake_ms"]["max"],
        ]
        for name, g in summary.items()
    ]
    lines = [
        common.table(
            ["requests", "n", "failed", "waited", "median ms", "p99 ms", "max ms"],
            rows,
            digits=3,
            title="local waits: t_stored of the frame waited for -> the local client returns (requests that waited)",
        )
    ]
    not_local = sum(g["not_local"] for name, g in summary.items() if not name.startswith("all"))
    if not_local:
        lines.append(f"WARNING: {not_local} replies did not come by the local path")
    rows = [
        [t["target"], t["value_ms"], f"<= {t['limit_ms']:g}", t["ratio"], common.verdict(t["passed"])] for t in tlist
    ]
    lines += [
        "",
        common.table(["target", "ms", "limit ms", "ratio", "verdict"], rows, digits=3, title="targets, local waits"),
    ]
    return "\n".join(lines)
