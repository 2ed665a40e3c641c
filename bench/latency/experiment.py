"""The paper's experiment (FxIS, section VI, Table II) as bench/latency/paper.py runs it: its
timing, one request and its metrics, the interleaved run, and Table II and the targets.

Every request is made by one (policy, path) series: a policy of POLICIES over a transport of
PATHS, the network path (Client(local="off"): the coordinator answers) or the local one
(Client(local="require"): the same-host client answers from the rings itself).
"""

from __future__ import annotations

import argparse
import math
import random
import time

from bench.shared import common

POLICIES = {
    "paper": {"sync": "independent", "wait": "next"},
    "ours": {"sync": "joint", "wait": "auto"},
}
SPIKE_MARGIN_MS = 2.0
# Table II of the paper: min, mean, max, std in ms (2 cameras, 20 fps, 100 requests)
PAPER_TABLE_II = {
    "eps_b": (0.36, 1.85, 49.27, 6.79),
    "eps'_b": (0.36, 0.89, 2.18, 0.28),
    "|eps_1|": (1.03, 13.35, 24.66, 6.89),
    "|eps_2|": (1.51, 13.33, 25.06, 6.78),
    "tau_w1": (2.49, 25.56, 48.98, 13.47),
    "tau_w2": (3.13, 26.48, 49.72, 13.48),
}
COLUMNS = ("min", "mean", "max", "std")
PATHS = {"network": "off", "local": "require"}  # transport -> Client(local=...)


# ---- the experiment's parameters -------------------------------------------------------------


def parse_phases(text: str) -> list[float]:
    try:
        phases = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a comma list of numbers (ms), got {text!r}") from None
    if not phases:
        raise argparse.ArgumentTypeError("expected at least one phase")
    return phases


def choice_list(choices: dict):
    """A parser of a comma list of distinct keys of ``choices`` ('both' for all of them)."""

    def parse(text: str) -> list[str]:
        names = [x.strip() for x in text.split(",") if x.strip()]
        if names == ["both"]:
            names = list(choices)
        unknown = [x for x in names if x not in choices]
        if unknown or not names or len(set(names)) != len(names):
            raise argparse.ArgumentTypeError(f"expected a comma list of {', '.join(choices)} (or 'both'), got {text!r}")
        return names

    return parse


parse_policies, parse_paths = choice_list(POLICIES), choice_list(PATHS)


def min_covering_arc(phases_ms: list[float], period_ms: float) -> float:
    """Length of the shortest arc of a circle of circumference ``period_ms`` that covers
    every phase (mod period): the smallest skew cameras with these phases can have."""
    points = sorted(p % period_ms for p in phases_ms)
    gaps = [b - a for a, b in zip(points, points[1:])] + [points[0] + period_ms - points[-1]]
    return period_ms - max(gaps)


class Experiment:
    """The timing the results are judged against."""

    def __init__(self, names: list[str], fps: float, phases_ms: list[float], jitter_ms: float):
        self.names, self.fps, self.phases_ms, self.jitter_ms = names, fps, phases_ms, jitter_ms
        self.period_ms = 1000.0 / fps  # tau_ia
        self.period_ns = round(1e9 / fps)
        self.min_allowed_skew_ms = min_covering_arc(phases_ms, self.period_ms)
        self.spike_threshold_ms = self.min_allowed_skew_ms + SPIKE_MARGIN_MS

    def as_dict(self) -> dict:
        return {
            "cameras": self.names,
            "fps": self.fps,
            "tau_ia_ms": self.period_ms,
            "phases_ms": self.phases_ms,
            "jitter_ms": self.jitter_ms,
            "min_allowed_skew_ms": self.min_allowed_skew_ms,
            "min_allowed_skew_definition": "shortest arc of the frame-period circle covering "
            "every configured phase_ms mod tau_ia (no jitter)",
            "spike_threshold_ms": self.spike_threshold_ms,
        }


# ---- measuring ------------------------------------------------------------------------------


def series_of(policies: list[str], paths: list[str]) -> list[tuple[str, str]]:
    """The (policy, path) pairs run, in the order they are interleaved."""
    return [(pol, path) for pol in policies for path in paths]


def label(series: tuple[str, str]) -> str:
    return f"{series[0]}, {series[1]}"


def by_series(records: list[dict], series: list[tuple[str, str]]) -> dict:
    """The successful requests of every series."""
    return {s: [r for r in records if (r["policy"], r["path"]) == s and r["error"] is None] for s in series}


def measure(client, exp: Experiment, policy: str, kinds_of: dict) -> dict:
    """One tuple request of ``policy`` and the paper's metrics for it."""
    modes = POLICIES[policy]
    rec = {"policy": policy, **modes, "error": None}
    t_send = time.monotonic_ns()
    try:
        reply = client.tuple(exp.names, sync=modes["sync"], wait=modes["wait"])
    except common.REQUEST_ERRORS as exc:
        rec.update(t_send=t_send, t_reply=time.monotonic_ns(), error=common.describe_error(exc))
        return rec
    t_reply = time.monotonic_ns()
    t_star, timing = reply.t_request, reply.timing
    t = {cam: reply[cam].t_capture for cam in exp.names}
    rec.update(
        t_send=t_send,
        t_reply=t_reply,
        rtt_ms=common.ms(t_reply - t_send),
        t_star=t_star,
        timing=timing,
        came_by=reply.path,
        frames={
            cam: {
                "frame_id": reply[cam].frame_id,
                "t_capture": reply[cam].t_capture,
                "t_stored": reply[cam].t_stored,
                "stamp_ok": common.stamp_ok(reply[cam], kinds_of.get(cam, "")),
            }
            for cam in exp.names
        },
        eps_ms={cam: common.ms(t_star - t[cam]) for cam in exp.names},
        eps_b_ms=common.ms(max(t.values()) - min(t.values())),
        tau_w_ms={cam: common.ms(timing["cameras"][cam]["waited"] - timing["received"]) for cam in exp.names},
    )
    rec["spike"] = rec["eps_b_ms"] > exp.spike_threshold_ms
    return rec


def fetch_context(client, exp: Experiment, t_star: int, offset_ns: int, delay_ns: int, reach: int = 2) -> dict:
    """Every camera's frames within ``reach`` periods of t*, as {camera: [[frame_id, t_capture]]}.

    Waits until the last of them is stored, then asks for the nearest frames to points half a
    period apart (every frame is the nearest one to some point), answered from the rings.
    """
    until_local = t_star - offset_ns + (reach + 0.5) * exp.period_ns + delay_ns + 20_000_000
    common.sleep_ms(common.ms(until_local - time.monotonic_ns()))
    frames: dict[str, dict[int, int]] = {cam: {} for cam in exp.names}
    for k in range(-2 * reach, 2 * reach + 1):
        reply = client.tuple(exp.names, at=int(t_star + k * exp.period_ns / 2), sync="independent", wait="none")
        for cam in exp.names:
            frames[cam][reply[cam].frame_id] = reply[cam].t_capture
    return {cam: sorted([fid, tc] for fid, tc in f.items()) for cam, f in frames.items()}


def run(args, clients: dict, exp: Experiment, kinds_of: dict, offset_ns: int, delay_ns: int) -> list[dict]:
    """args.requests requests of every series, interleaved, each after its random sleep;
    ``clients``: path -> Client."""
    rng = random.Random(args.seed)
    series = series_of(args.policies, list(clients))
    schedule = [s for _ in range(args.requests) for s in series]
    worst = {s: -1.0 for s in series}
    count = {s: 0 for s in series}
    records = []
    with common.progress(len(schedule), "latency, Table II") as bar:
        for i, (policy, path) in enumerate(schedule):
            sleep = args.sleep_ms + rng.uniform(-args.fluct_ms, args.fluct_ms)
            late = common.sleep_late_ms(sleep)
            rec = measure(clients[path], exp, policy, kinds_of)
            rec.update(i=i, k=count[policy, path], path=path, sleep_ms=sleep, sleep_late_ms=late)
            count[policy, path] += 1
            if rec["error"] is None and rec["eps_b_ms"] > worst[policy, path]:
                # the largest eps_b so far: keep the frames around it for the Fig. 7 plot
                worst[policy, path] = rec["eps_b_ms"]
                try:
                    rec["context"] = fetch_context(clients[path], exp, rec["t_star"], offset_ns, delay_ns)
                except common.REQUEST_ERRORS as exc:
                    rec["context_error"] = common.describe_error(exc)
            records.append(rec)
            bar.update(1)
    return records


# ---- results --------------------------------------------------------------------------------


def _circular_mean(values_ns: list[int], period_ns: int) -> float:
    angles = [2 * math.pi * (v % period_ns) / period_ns for v in values_ns]
    s, c = sum(map(math.sin, angles)), sum(map(math.cos, angles))
    return (math.atan2(s, c) % (2 * math.pi)) * period_ns / (2 * math.pi)


def observed_phases(records: list[dict], exp: Experiment) -> dict | None:
    """The cameras' phases as seen in the frames' capture times, relative to the first camera."""
    times = {cam: [] for cam in exp.names}
    for r in records:
        for cam, f in r.get("frames", {}).items():
            times[cam].append(f["t_capture"])
    if not all(times.values()):
        return None
    mean = {cam: _circular_mean(v, exp.period_ns) for cam, v in times.items()}
    ref = mean[exp.names[0]]
    rel = {cam: ((m - ref) % exp.period_ns) / 1e6 for cam, m in mean.items()}
    configured = {cam: (p - exp.phases_ms[0]) % exp.period_ms for cam, p in zip(exp.names, exp.phases_ms)}
    diff = {
        cam: abs((rel[cam] - configured[cam] + exp.period_ms / 2) % exp.period_ms - exp.period_ms / 2)
        for cam in exp.names
    }
    return {
        "relative_ms": rel,
        "configured_relative_ms": configured,
        "difference_ms": diff,
        "min_covering_arc_ms": min_covering_arc(list(rel.values()), exp.period_ms),
    }


def policy_rows(recs: list[dict], exp: Experiment) -> dict[str, dict]:
    """Table II's rows for one policy's successful requests: name -> summary (ms)."""
    eps_b = [r["eps_b_ms"] for r in recs]
    mean_b = sum(eps_b) / len(eps_b) if eps_b else 0.0
    rows = {"eps_b": common.summary(eps_b), "eps'_b": common.summary([e for e in eps_b if e < mean_b])}
    for j, cam in enumerate(exp.names, 1):
        rows[f"|eps_{j}|"] = common.summary([abs(r["eps_ms"][cam]) for r in recs])
    for j, cam in enumerate(exp.names, 1):
        rows[f"tau_w{j}"] = common.summary([r["tau_w_ms"][cam] for r in recs])
    return rows


def check_targets(recs: list[dict], exp: Experiment) -> list[dict]:
    """The three targets on one policy's successful requests."""
    tau = exp.period_ms
    eps_b = [r["eps_b_ms"] for r in recs]
    waits = [w for r in recs for w in r["tau_w_ms"].values()]
    eps = [abs(e) for r in recs for e in r["eps_ms"].values()]
    spikes = sum(1 for e in eps_b if e > exp.spike_threshold_ms)
    out = []

    def target(key, text, value, limit, extra=""):
        passed = None if value is None else value <= limit
        out.append(
            {"target": key, "text": text, "value_ms": value, "limit_ms": limit, "passed": passed, "extra": extra}
        )

    target(
        "a",
        "no spikes: max eps_b <= min_allowed_skew + 2 ms",
        max(eps_b) if eps_b else None,
        exp.spike_threshold_ms,
        f"{spikes} spike(s)",
    )
    # tau_ia/8 is the mean wait over t* spread evenly across the frame period; the mean over n
    # random t* misses it by about std/sqrt(n) from the draw alone (0.9 ms for 100 requests, as
    # much as the 1 ms allowed for delivery), so twice that standard error is allowed too. And
    # tau_w ends when the service is woken by the frame: on a loaded machine the scheduler's
    # delay in waking it (how late the bench's own sleeps before these requests ended) is in
    # every tau_w and no policy's doing, so its mean is allowed as well.
    late = [r["sleep_late_ms"] for r in recs if r.get("sleep_late_ms") is not None]
    late_mean = sum(late) / len(late) if late else 0.0
    per_request = [sum(r["tau_w_ms"].values()) / len(r["tau_w_ms"]) for r in recs if r["tau_w_ms"]]
    draw = 2 * common.summary(per_request)["std"] / math.sqrt(len(per_request)) if len(per_request) > 1 else 0.0
    target(
        "b",
        f"mean tau_w (all cameras) <= tau_ia/8 + 1 ms + 2 standard errors of the random t* {draw:.2f} ms "
        f"+ this machine's mean wake-up delay {late_mean:.2f} ms",
        sum(waits) / len(waits) if waits else None,
        tau / 8 + 1.0 + draw + late_mean,
    )
    target(
        "c",
        "max |eps_j| <= tau_ia/2 + min_allowed_skew + 2 ms",
        max(eps) if eps else None,
        tau / 2 + exp.min_allowed_skew_ms + SPIKE_MARGIN_MS,
    )
    return out


def format_table_ii(series: tuple[str, str], rows: dict[str, dict], exp: Experiment, n: int) -> str:
    names = {f"|eps_{j}|": f"|eps_{j}| ({cam})" for j, cam in enumerate(exp.names, 1)}
    names.update({f"tau_w{j}": f"tau_w{j} ({cam})" for j, cam in enumerate(exp.names, 1)})
    table_rows = []
    for key, s in rows.items():
        paper = PAPER_TABLE_II.get(key, (None,) * 4)
        table_rows.append([names.get(key, key), *(s[c] for c in COLUMNS), *paper])
    policy, path = series
    modes = POLICIES[policy]
    transport = (
        f" path (Client(local={PATHS[path]!r}))" if path in PATHS else ""
    )  # else a label (bench/network/remote.py)
    title = (
        f"Table II, policy {policy!r} (sync={modes['sync']}, wait={modes['wait']}), {path}{transport}"
        f": {n} requests, ms; right: the paper's published numbers"
    )
    return common.table(
        ["metric", *COLUMNS, "paper min", "mean", "max", "std"], table_rows, title=title, separators=[5]
    )


def format_targets(name: str, targets: list[dict]) -> list[str]:
    lines = []
    for t in targets:
        verdict = f"{common.verdict(t['passed']):4}"
        value = "-" if t["value_ms"] is None else f"{t['value_ms']:.2f}"
        extra = f" ({t['extra']})" if t["extra"] else ""
        lines.append(f"{verdict} ({t['target']}) {name}: {t['text']}: {value} <= {t['limit_ms']:.2f} ms{extra}")
    return lines
