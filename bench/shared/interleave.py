"""Timing contenders interleaved: every round times one sample of each contender, in a random
order, each after a random sleep, so a drift of the machine's speed hits all of them alike.
Then the hot loop: each contender called back to back (no sleep, its caches and threads warm),
in blocks, the contenders in a random order in every block.

Not a public module: the benches import it as ``bench.shared.interleave``.
"""

from __future__ import annotations

import random
import resource
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench.shared import common


@dataclass
class Contender:
    """``fn()`` is timed; ``check(result)`` runs afterwards, untimed, and raises if it is wrong."""

    name: str
    fn: Callable[[], Any]
    check: Callable[[Any], None] = lambda result: None
    samples: list = field(default_factory=list)  # ms, None for a failed sample
    faults: list = field(default_factory=list)  # minor page faults of this process per sample
    errors: list = field(default_factory=list)  # (sample index, error)
    first_traceback: str | None = None
    warmup_failed: int = 0
    hot: list = field(default_factory=list)  # ms of each back-to-back call; None for a failed one


def minor_faults() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt


def time_once(c: Contender) -> tuple[float | None, int, str | None, str | None]:
    """One sample: (ms or None, minor page faults during the call, error or None, traceback
    or None); never raises."""
    f0 = minor_faults()
    try:
        t0 = time.perf_counter_ns()
        result = c.fn()
        elapsed = time.perf_counter_ns() - t0
        faults = minor_faults() - f0
        c.check(result)
        del result
        return elapsed / common.NS_PER_MS, faults, None, None
    except Exception as exc:  # recorded and counted, never raised
        return None, minor_faults() - f0, common.describe_error(exc), traceback.format_exc()


def record(c: Contender, sample: tuple) -> None:
    ms, faults, error, tb = sample
    c.samples.append(ms)
    c.faults.append(faults)
    if error is not None:
        c.errors.append((len(c.samples) - 1, error))
        c.first_traceback = c.first_traceback or tb


def time_contenders(
    contenders: list[Contender], n: int, warmup: int, rng: random.Random, sleep_max_ms: float, desc: str
) -> None:
    """``warmup`` then ``n`` rounds; each round one sample of every contender in a random order."""
    for _ in range(warmup):
        for c in contenders:
            c.warmup_failed += time_once(c)[2] is not None
    with common.progress(n * len(contenders), desc) as bar:
        for _ in range(n):
            for c in rng.sample(contenders, len(contenders)):
                common.sleep_ms(rng.uniform(0.0, sleep_max_ms))
                record(c, time_once(c))
                bar.update(1)


def hot_loops(contenders: list[Contender], calls: int, rng: random.Random, desc: str, blocks: int = 10) -> None:
    """``calls`` back-to-back calls of every contender, in ``blocks`` blocks (each contender's block
    in a random order within a round): no sleep between calls, each call timed on its own, its
    check run untimed after it."""
    per_block = [calls // blocks + (b < calls % blocks) for b in range(blocks)]
    with common.progress(calls * len(contenders), desc) as bar:
        for n in per_block:
            for c in rng.sample(contenders, len(contenders)):
                for _ in range(n):
                    c.hot.append(time_once(c)[0])
                bar.update(n)


def cycle(items: list) -> Callable[[], Any]:
    """Returns the next of ``items`` on every call, round and round."""
    state = {"i": -1}

    def next_item():
        state["i"] = (state["i"] + 1) % len(items)
        return items[state["i"]]

    return next_item


def result_of(c: Contender) -> dict:
    """What the JSON keeps of a contender: summary, failures and every raw sample."""
    ok = [v for v in c.samples if v is not None]
    return {
        "summary_ms": common.summary(ok),
        "failed": len(c.errors),
        "warmup_failed": c.warmup_failed,
        "errors": c.errors[:20],
        "first_traceback": c.first_traceback,
        "minor_faults_median": float(np.median(c.faults)) if c.faults else None,
        "samples_ms": c.samples,
        "minor_faults": c.faults,
        HOT: common.summary(v for v in c.hot if v is not None),
        "hot_failed": sum(v is None for v in c.hot),
        "hot_samples_ms": c.hot,
    }


HOT = "hot_ms"  # a result's summary of its hot loop


def median(results: dict, name: str, key: str = "summary_ms") -> float | None:
    """The median of contender ``name``'s samples (``key``: "summary_ms", interleaved with
    sleeps; HOT, the hot loop); None if it was not measured."""
    r = results.get(name)
    return r[key]["median"] if r and key in r else None


def ratio(a: float | None, b: float | None) -> float | None:
    return a / b if a is not None and b else None
