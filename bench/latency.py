"""The paper's experiment (FxIS, section VI): accuracy and waiting time of tuple requests.

Launches a service with N synthetic cameras (default 2 at 20 fps, 1360x1024 mono8, the second
1 ms behind the first, timing jitter +/-0.3 ms on both, rings of 20 slots) unless --endpoint is
given. Then it requests tuples of all cameras at random instants: before every request it
sleeps tau_sleep + U[-tau_mf, tau_mf] (defaults 180 and 50 ms), as in the paper's eq. (3).

Both policies run on the same service, interleaved request by request (paper, ours, paper,
ours, ...; every request after its own random sleep), so they see the same conditions:

  paper   sync="independent", wait="next": every camera's nearest frame to t*, chosen on its
          own, after waiting for the next frame of every camera (the paper's FxIS).
  ours    sync="joint", wait="auto": the tuple of least skew near t*, waiting only while a
          camera's next frame could still be nearer to t* than its newest stored one.

Per request: t* (the reply's t_request), per camera the chosen frame's capture time t_j,
eps_j = t* - t_j, eps_b = max_j t_j - min_j t_j (the skew), tau_w_j = the moment the service
stopped waiting for camera j (timing.cameras[j].waited) - the moment it received the request.
eps'_b is eps_b over the requests whose eps_b < mean(eps_b) of that policy (paper eq. 7,
g(T) = mean). Table II is printed per policy next to the paper's published numbers.

Spikes. min_allowed_skew is the smallest skew the camera timing allows at all: the shortest
arc of the circle of one frame period (tau_ia = 1/fps) that covers every camera's configured
phase (phase_ms mod tau_ia), with nothing added for jitter. E.g. phases 0,1 at 20 fps: 1 ms;
phases 0,10,30: 30 ms. It uses the configured --phases, not measured frame times (the
phases observed in the replies are printed as a cross-check). A request is a spike when
eps_b > min_allowed_skew + 2 ms.

Targets, checked on our policy (PASS/FAIL lines; also shown for the paper's for reference):
  (a) no spikes: eps_b <= min_allowed_skew + 2 ms for every request;
  (b) mean tau_w over all cameras and requests <= tau_ia/8 + 1 ms;
  (c) max |eps_j| <= tau_ia/2 + min_allowed_skew + 2 ms.

Writes latency.json (every request: times, timing record, frames, metrics; the summary) and
figures like the paper's: latency_fig5_eps.png (eps_j per request), latency_fig6_skew.png
(eps_b per request, both policies), latency_fig7_spike.png (frame times around the request
with the largest eps_b of each policy, chosen frames highlighted; the neighbouring frames are
fetched from the service right after such a request) and latency_fig8_wait.png (tau_w).

Exit status: 0 when the run completed (whatever the targets say); 1 if a request failed or
with --strict if a target failed; 2 on bad flags.
"""
from __future__ import annotations

import argparse
import math
import os
import random
import sys
import time

if __package__:
    from . import _common as common
else:  # run as a script, or loaded from its path
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import _common as common

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


# ---- the experiment's parameters -------------------------------------------------------------

def parse_phases(text: str) -> list[float]:
    try:
        phases = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a comma list of numbers (ms), got {text!r}") from None
    if not phases:
        raise argparse.ArgumentTypeError("expected at least one phase")
    return phases


def parse_policies(text: str) -> list[str]:
    names = [x.strip() for x in text.split(",") if x.strip()]
    if names == ["both"]:
        names = list(POLICIES)
    unknown = [x for x in names if x not in POLICIES]
    if unknown or not names or len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(
            f"expected a comma list of {', '.join(POLICIES)} (or 'both'), got {text!r}")
    return names


def min_covering_arc(phases_ms: list[float], period_ms: float) -> float:
    """Length of the shortest arc of a circle of circumference ``period_ms`` that covers
    every phase (mod period): the smallest skew cameras with these phases can have."""
    points = sorted(p % period_ms for p in phases_ms)
    gaps = [b - a for a, b in zip(points, points[1:])] + [points[0] + period_ms - points[-1]]
    return period_ms - max(gaps)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="latency.py", description=__doc__,
                                formatter_class=common.HelpFormatter)
    p.add_argument("-n", "--requests", type=common.positive_int, default=100,
                   help="requests per policy (the paper: 100)")
    p.add_argument("--sleep-ms", type=common.nonnegative_float, default=180.0,
                   help="tau_sleep: basic sleep before each request, ms")
    p.add_argument("--fluct-ms", type=common.nonnegative_float, default=50.0,
                   help="tau_mf: the sleep varies uniformly by +/- this, ms")
    p.add_argument("--policies", type=parse_policies, default=",".join(POLICIES),
                   help="comma list of paper, ours (or 'both'); run interleaved in this order")
    p.add_argument("--strict", action="store_true",
                   help="exit 1 if a target fails on our policy")
    cams = p.add_argument_group("cameras (with --endpoint they must describe the running service)")
    cams.add_argument("--cameras", type=common.positive_int, default=None,
                      help="number of synthetic cameras cam0, cam1, ... (default: 2, or as many "
                           "as --phases lists)")
    cams.add_argument("--fps", type=common.positive_float, default=20.0, help="frame rate of every camera")
    cams.add_argument("--phases", type=parse_phases, default=None,
                      help="comma list of phase_ms per camera (default: 0,1 for two cameras; "
                           "0,1,...,N-1 for N)")
    cams.add_argument("--jitter-ms", type=common.nonnegative_float, default=0.3,
                      help="uniform capture-time jitter +/- ms of every camera")
    cams.add_argument("--width", type=common.positive_int, default=1360)
    cams.add_argument("--height", type=common.positive_int, default=1024)
    cams.add_argument("--slots", type=common.positive_int, default=20, help="frames per camera ring")
    common.add_service_args(p, "--fps and --phases must then describe it: the cameras' "
                               "count and fps are checked against its status")
    return p


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
            "cameras": self.names, "fps": self.fps, "tau_ia_ms": self.period_ms,
            "phases_ms": self.phases_ms, "jitter_ms": self.jitter_ms,
            "min_allowed_skew_ms": self.min_allowed_skew_ms,
            "min_allowed_skew_definition": "shortest arc of the frame-period circle covering "
                                           "every configured phase_ms mod tau_ia (no jitter)",
            "spike_threshold_ms": self.spike_threshold_ms,
        }


# ---- measuring ------------------------------------------------------------------------------

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
        t_send=t_send, t_reply=t_reply, rtt_ms=common.ms(t_reply - t_send),
        t_star=t_star, timing=timing,
        frames={cam: {"frame_id": reply[cam].frame_id, "t_capture": reply[cam].t_capture,
                      "t_stored": reply[cam].t_stored,
                      "stamp_ok": common.stamp_ok(reply[cam], kinds_of.get(cam, ""))}
                for cam in exp.names},
        eps_ms={cam: common.ms(t_star - t[cam]) for cam in exp.names},
        eps_b_ms=common.ms(max(t.values()) - min(t.values())),
        tau_w_ms={cam: common.ms(timing["cameras"][cam]["waited"] - timing["received"])
                  for cam in exp.names},
    )
    rec["spike"] = rec["eps_b_ms"] > exp.spike_threshold_ms
    return rec


def fetch_context(client, exp: Experiment, t_star: int, offset_ns: int, delay_ns: int,
                  reach: int = 2) -> dict:
    """Every camera's frames within ``reach`` periods of t*, as {camera: [[frame_id, t_capture]]}.

    Waits until the last of them is stored, then asks for the nearest frames to points half a
    period apart (every frame is the nearest one to some point), answered from the rings.
    """
    until_local = t_star - offset_ns + (reach + 0.5) * exp.period_ns + delay_ns + 20_000_000
    common.sleep_ms(common.ms(until_local - time.monotonic_ns()))
    frames: dict[str, dict[int, int]] = {cam: {} for cam in exp.names}
    for k in range(-2 * reach, 2 * reach + 1):
        reply = client.tuple(exp.names, at=int(t_star + k * exp.period_ns / 2),
                             sync="independent", wait="none")
        for cam in exp.names:
            frames[cam][reply[cam].frame_id] = reply[cam].t_capture
    return {cam: sorted([fid, tc] for fid, tc in f.items()) for cam, f in frames.items()}


def run(args, client, exp: Experiment, kinds_of: dict, offset_ns: int, delay_ns: int) -> list[dict]:
    rng = random.Random(args.seed)
    schedule = [pol for _ in range(args.requests) for pol in args.policies]
    worst = {pol: -1.0 for pol in args.policies}
    count = {pol: 0 for pol in args.policies}
    records = []
    with common.progress(len(schedule), "latency") as bar:
        for i, policy in enumerate(schedule):
            sleep = args.sleep_ms + rng.uniform(-args.fluct_ms, args.fluct_ms)
            common.sleep_ms(sleep)
            rec = measure(client, exp, policy, kinds_of)
            rec.update(i=i, k=count[policy], sleep_ms=sleep)
            count[policy] += 1
            if rec["error"] is None and rec["eps_b_ms"] > worst[policy]:
                # the largest eps_b so far: keep the frames around it for the Fig. 7 plot
                worst[policy] = rec["eps_b_ms"]
                try:
                    rec["context"] = fetch_context(client, exp, rec["t_star"], offset_ns, delay_ns)
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
    diff = {cam: abs((rel[cam] - configured[cam] + exp.period_ms / 2) % exp.period_ms - exp.period_ms / 2)
            for cam in exp.names}
    return {"relative_ms": rel, "configured_relative_ms": configured, "difference_ms": diff,
            "min_covering_arc_ms": min_covering_arc(list(rel.values()), exp.period_ms)}


def policy_rows(recs: list[dict], exp: Experiment) -> dict[str, dict]:
    """Table II's rows for one policy's successful requests: name -> summary (ms)."""
    eps_b = [r["eps_b_ms"] for r in recs]
    mean_b = sum(eps_b) / len(eps_b) if eps_b else 0.0
    rows = {"eps_b": common.summary(eps_b),
            "eps'_b": common.summary([e for e in eps_b if e < mean_b])}
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
        out.append({"target": key, "text": text, "value_ms": value, "limit_ms": limit,
                    "passed": passed, "extra": extra})

    target("a", "no spikes: max eps_b <= min_allowed_skew + 2 ms", max(eps_b) if eps_b else None,
           exp.spike_threshold_ms, f"{spikes} spike(s)")
    target("b", "mean tau_w (all cameras) <= tau_ia/8 + 1 ms",
           sum(waits) / len(waits) if waits else None, tau / 8 + 1.0)
    target("c", "max |eps_j| <= tau_ia/2 + min_allowed_skew + 2 ms", max(eps) if eps else None,
           tau / 2 + exp.min_allowed_skew_ms + SPIKE_MARGIN_MS)
    return out


def format_table_ii(policy: str, rows: dict[str, dict], exp: Experiment, n: int) -> str:
    names = {f"|eps_{j}|": f"|eps_{j}| ({cam})" for j, cam in enumerate(exp.names, 1)}
    names.update({f"tau_w{j}": f"tau_w{j} ({cam})" for j, cam in enumerate(exp.names, 1)})
    table_rows = []
    for key, s in rows.items():
        paper = PAPER_TABLE_II.get(key, (None,) * 4)
        table_rows.append([names.get(key, key), *(s[c] for c in COLUMNS), *paper])
    modes = POLICIES[policy]
    title = (f"Table II, policy {policy!r} (sync={modes['sync']}, wait={modes['wait']}): "
             f"{n} requests, ms; right: the paper's published numbers")
    return common.table(["metric", *COLUMNS, "paper min", "mean", "max", "std"], table_rows,
                        title=title, separators=[5])


def format_targets(policy: str, targets: list[dict]) -> list[str]:
    lines = []
    for t in targets:
        verdict = {True: "PASS", False: "FAIL", None: "N/A "}[t["passed"]]
        value = "-" if t["value_ms"] is None else f"{t['value_ms']:.2f}"
        extra = f" ({t['extra']})" if t["extra"] else ""
        lines.append(f"{verdict} ({t['target']}) {policy}: {t['text']}: {value} <= "
                     f"{t['limit_ms']:.2f} ms{extra}")
    return lines


# ---- figures --------------------------------------------------------------------------------

POLICY_COLOR = {"paper": "tab:red", "ours": "tab:blue"}


def _by_policy(records, policies):
    return {pol: [r for r in records if r["policy"] == pol and r["error"] is None] for pol in policies}


def figures(records: list[dict], exp: Experiment, policies: list[str], out: str, subtitle: str) -> list[str]:
    plt = common.pyplot()
    by = _by_policy(records, policies)
    paths = []

    def save(fig, name):
        fig.suptitle(subtitle, fontsize=9)
        fig.tight_layout()
        path = os.path.join(out, name)
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)

    # Fig. 5: eps_j per request
    fig, axes = plt.subplots(len(policies), 1, figsize=(11, 3.4 * len(policies)), squeeze=False,
                             sharex=True, sharey=True)
    for ax, pol in zip(axes[:, 0], policies):
        for j, cam in enumerate(exp.names, 1):
            ax.plot([r["k"] for r in by[pol]], [r["eps_ms"][cam] for r in by[pol]], ".-", lw=0.7,
                    ms=4, label=f"eps_{j} ({cam})")
        for y in (-exp.period_ms / 2, exp.period_ms / 2):
            ax.axhline(y, color="grey", ls=":", lw=0.8)
        ax.axhline(0, color="black", lw=0.5)
        ax.set_title(f"{pol}: eps_j = t* - t_j (signed); dotted: +/- tau_ia/2", fontsize=10)
        ax.set_ylabel("ms")
        ax.legend(fontsize=8, loc="upper right")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("request")
    save(fig, "latency_fig5_eps.png")

    # Fig. 6: eps_b per request, both policies; full scale and zoomed
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.2))
    for ax, zoom in zip(axes, (False, True)):
        for pol in policies:
            ax.plot([r["k"] for r in by[pol]], [r["eps_b_ms"] for r in by[pol]], ".-", lw=0.7, ms=4,
                    color=POLICY_COLOR[pol], label=f"{pol} ({sum(r['spike'] for r in by[pol])} spikes)")
        ax.axhline(exp.spike_threshold_ms, color="black", ls="--", lw=0.8,
                   label=f"spike threshold {exp.spike_threshold_ms:.2f} ms")
        ax.axhline(exp.min_allowed_skew_ms, color="grey", ls=":", lw=0.8,
                   label=f"min allowed skew {exp.min_allowed_skew_ms:.2f} ms")
        if zoom:
            ax.set_ylim(max(0.0, exp.min_allowed_skew_ms - 2.0), exp.spike_threshold_ms + 1.5)
            ax.set_title("eps_b, zoomed on the threshold", fontsize=10)
        else:
            ax.set_title("eps_b = max t_j - min t_j per request", fontsize=10)
        ax.set_xlabel("request")
        ax.set_ylabel("ms")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    save(fig, "latency_fig6_skew.png")

    # Fig. 7: frames around the request with the largest eps_b of each policy
    fig, axes = plt.subplots(len(policies), 1, figsize=(11, 1.2 + 1.1 * len(exp.names) * len(policies)),
                             squeeze=False)
    for ax, pol in zip(axes[:, 0], policies):
        if not by[pol]:
            ax.set_axis_off()
            continue
        worst = max(by[pol], key=lambda r: r["eps_b_ms"])
        t_star = worst["t_star"]
        for j, cam in enumerate(exp.names):
            context = worst.get("context", {}).get(cam, [])
            xs = [common.ms(tc - t_star) for _, tc in context]
            ax.plot(xs, [j] * len(xs), "o", mfc="white", mec="grey", ms=8,
                    label="stored frames" if j == 0 else None)
            for fid, tc in context:
                ax.annotate(str(fid), (common.ms(tc - t_star), j), textcoords="offset points",
                            xytext=(0, 8), ha="center", fontsize=7, color="grey")
            chosen = worst["frames"][cam]["t_capture"]
            ax.plot([common.ms(chosen - t_star)], [j], "o", color=POLICY_COLOR[pol], ms=9,
                    label="chosen frame" if j == 0 else None)
        ax.axvline(0, color="purple", lw=1.5, label="t*")
        for x in (-exp.period_ms / 2, exp.period_ms / 2):
            ax.axvline(x, color="purple", ls=":", lw=0.8)
        ax.set_yticks(range(len(exp.names)), exp.names)
        ax.set_ylim(-0.7, len(exp.names) - 0.3)
        xs = [common.ms(tc - t_star) for frames in worst.get("context", {}).values() for _, tc in frames]
        xs += [common.ms(f["t_capture"] - t_star) for f in worst["frames"].values()]
        ax.set_xlim(min(xs + [-exp.period_ms]) - 8, max(xs + [exp.period_ms]) + 8)
        ax.set_xlabel("capture time - t*, ms (dotted: t* +/- tau_ia/2; numbers: frame ids)")
        ax.set_title(f"{pol}: request {worst['k']} with the largest eps_b = {worst['eps_b_ms']:.2f} ms"
                     + ("" if "context" in worst else " (neighbouring frames not fetched)"), fontsize=10)
        ax.grid(axis="x", alpha=0.3)
        ax.legend(fontsize=8, loc="upper right", ncol=3)
    save(fig, "latency_fig7_spike.png")

    # Fig. 8: tau_w per request
    fig, axes = plt.subplots(len(policies), 1, figsize=(11, 3.4 * len(policies)), squeeze=False,
                             sharex=True, sharey=True)
    for ax, pol in zip(axes[:, 0], policies):
        for j, cam in enumerate(exp.names, 1):
            ax.plot([r["k"] for r in by[pol]], [r["tau_w_ms"][cam] for r in by[pol]], ".-", lw=0.7,
                    ms=4, label=f"tau_w{j} ({cam})")
        waits = [w for r in by[pol] for w in r["tau_w_ms"].values()]
        if waits:
            ax.axhline(sum(waits) / len(waits), color="black", ls="--", lw=0.8,
                       label=f"mean {sum(waits) / len(waits):.2f} ms")
        ax.axhline(exp.period_ms / 8 + 1, color="grey", ls=":", lw=0.8, label="target tau_ia/8 + 1 ms")
        ax.set_title(f"{pol}: tau_w = time the service waited for each camera", fontsize=10)
        ax.set_ylabel("ms")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel("request")
    save(fig, "latency_fig8_wait.png")
    return paths


# ---- main -----------------------------------------------------------------------------------

def _service_cameras(status: dict, args, names: list[str]) -> str | None:
    """Why the running service does not match the flags, or None."""
    cams = status["cameras"]
    if sorted(cams) != sorted(names):
        return (f"the service has cameras {sorted(cams)}, the flags describe {names}; pass "
                f"--cameras/--phases to match (this bench expects cameras named cam0, cam1, ...)")
    for name, cam in cams.items():
        fps = cam.get("fps")
        if fps and abs(fps - args.fps) > 0.02 * args.fps:
            return f"camera {name} runs at {fps} fps, not --fps {args.fps:g}"
    return None


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = common.parse_args(p, argv)
    if isinstance(args, int):
        return args
    n_cams = args.cameras or (len(args.phases) if args.phases else 2)
    phases = args.phases or [float(j) for j in range(n_cams)]
    if len(phases) != n_cams:
        return common.usage_error(p, f"--phases lists {len(phases)} phase(s) for {n_cams} camera(s)")
    period_ms = 1000.0 / args.fps
    if args.jitter_ms * 2 >= period_ms:
        return common.usage_error(p, f"--jitter-ms must be below half the frame period ({period_ms / 2:.3f} ms)")
    names = [f"cam{j}" for j in range(n_cams)]
    exp = Experiment(names, args.fps, phases, args.jitter_ms)
    out = common.ensure_dir(args.out)
    run_args = common.synthetic_camera_flags(names, args.fps, args.width, args.height, phases,
                                             args.jitter_ms) + ["--slots", str(args.slots)]
    started = time.time()
    host = common.host_info()  # before the service starts: the code it runs
    try:
        with common.service(args.endpoint, run_args, os.path.join(out, "latency.service.log"),
                            args.timeout) as (client, info):
            status = common.wait_until_streaming(client)
            if args.endpoint:
                problem = _service_cameras(status, args, names)
                if problem:
                    print(f"latency: {problem}", file=sys.stderr)
                    return common.EXIT_USAGE
            sent = time.monotonic_ns()
            offset_ns = client.time() - (sent + time.monotonic_ns()) // 2
            delay_ns = int(max(c.get("delay_ms") or 0 for c in status["cameras"].values()) * 1e6)
            kinds_of = {cam: c["kind"] for cam, c in status["cameras"].items()}
            records = run(args, client, exp, kinds_of, offset_ns, delay_ns)
            status_after = client.status()
    except RuntimeError as exc:
        print(f"latency: {exc}", file=sys.stderr)
        return common.EXIT_FAILED

    by = _by_policy(records, args.policies)
    failed = [r for r in records if r["error"] is not None]
    bad_stamps = sum(1 for r in records for f in r.get("frames", {}).values() if f["stamp_ok"] is False)
    phases_seen = observed_phases(records, exp)
    cam0 = status["cameras"][names[0]]
    subtitle = (f"{n_cams} cameras {cam0['shape'][1]}x{cam0['shape'][0]} at {args.fps:g} fps, phases "
                f"{','.join(f'{x:g}' for x in phases)} ms, jitter +/-{args.jitter_ms:g} ms, "
                f"{cam0.get('ring_slots')} slots; sleeps {args.sleep_ms:g} +/- {args.fluct_ms:g} ms")
    print(f"latency: {subtitle}; {args.requests} requests per policy, interleaved "
          f"({' / '.join(args.policies)}); seed {args.seed}")
    print(common.code_line(host["code"]))
    print(f"tau_ia = {exp.period_ms:.2f} ms; min_allowed_skew = {exp.min_allowed_skew_ms:.2f} ms "
          f"(shortest arc covering the configured phases mod tau_ia); spike: eps_b > "
          f"{exp.spike_threshold_ms:.2f} ms")
    if phases_seen:
        rel = ", ".join(f"{cam} {v:.2f}" for cam, v in phases_seen["relative_ms"].items())
        print(f"observed phases relative to {names[0]} (ms, circular mean of capture times mod tau_ia): "
              f"{rel}; covering arc {phases_seen['min_covering_arc_ms']:.2f} ms")
        off = {c: d for c, d in phases_seen["difference_ms"].items() if d > 1.0}
        if off:
            print("WARNING: observed phases differ from --phases by more than 1 ms: "
                  + ", ".join(f"{cam} by {d:.2f} ms" for cam, d in off.items()))

    summary = {}
    for pol in args.policies:
        recs = by[pol]
        rows = policy_rows(recs, exp)
        targets = check_targets(recs, exp)
        summary[pol] = {"requests": len(recs), "failed": sum(r["policy"] == pol for r in failed),
                        "spikes": sum(r["spike"] for r in recs),
                        "mean_eps_b_ms_for_eps_prime": rows["eps_b"]["mean"],
                        "table_ii_ms": rows, "targets": targets,
                        "rtt_ms": common.summary([r["rtt_ms"] for r in recs])}
        print()
        print(format_table_ii(pol, rows, exp, len(recs)))
        print(f"spikes ({pol}): {summary[pol]['spikes']} of {len(recs)} requests with eps_b > "
              f"{exp.spike_threshold_ms:.2f} ms")

    strict_failed = False
    print()
    if "ours" in args.policies:
        print("targets, checked on our policy (sync=joint, wait=auto):")
        for line in format_targets("ours", summary["ours"]["targets"]):
            print("  " + line)
        strict_failed = any(t["passed"] is not True for t in summary["ours"]["targets"])
    if "paper" in args.policies:
        print("for reference, the same targets on the paper's policy:")
        for line in format_targets("paper", summary["paper"]["targets"]):
            print("  " + line)
    print(f"failed requests: {len(failed)}; frames whose pixel stamp did not match their id: {bad_stamps}")
    for r in failed[:10]:
        print(f"  failed: request {r['i']} ({r['policy']}): {r['error']}")

    json_path = os.path.join(out, "latency.json")
    common.write_json(json_path, {
        "benchmark": "latency",
        "started_unix": started,
        "argv": sys.argv[1:] if argv is None else list(argv),
        "settings": vars(args),
        "experiment": exp.as_dict(),
        "policies": {pol: POLICIES[pol] for pol in args.policies},
        "service": info,
        "host": host,
        "status_before": status,
        "status_after": status_after,
        "clock": "CLOCK_MONOTONIC ns; t_send/t_reply are the bench's time.monotonic_ns(); "
                 "t_star, t_capture and timing are the service's",
        "clock_offset_ns": offset_ns,
        "observed_phases": phases_seen,
        "paper_table_ii_ms": {k: dict(zip(COLUMNS, v)) for k, v in PAPER_TABLE_II.items()},
        "summary": summary,
        "failed": len(failed),
        "stamp_mismatches": bad_stamps,
        "records": records,
    })
    paths = figures(records, exp, args.policies, out, subtitle)
    print(f"wrote {json_path}, " + ", ".join(os.path.basename(x) for x in paths))
    if failed:
        return common.EXIT_FAILED
    if args.strict and strict_failed:
        return common.EXIT_FAILED
    return common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
