"""The paper's experiment (FxIS, section VI): accuracy and waiting time of tuple requests.

Launches a service with N synthetic cameras (default 2 at 20 fps, 1360x1024 mono8, the second
1 ms behind the first, timing jitter +/-0.3 ms on both, rings of 20 slots) unless --endpoint is
given. Then it requests tuples of all cameras at random instants: before every request it
sleeps tau_sleep + U[-tau_mf, tau_mf] (defaults 180 and 50 ms), as in the paper's eq. (3).

Both policies run on the same service, each over both paths (--paths), interleaved request
by request (paper network, paper local, ours network, ours local, paper network, ...; every
request after its own random sleep), so they see the same conditions:

  paper   sync="independent", wait="next": every camera's nearest frame to t*, chosen on its
          own, after waiting for the next frame of every camera (the paper's FxIS).
  ours    sync="joint", wait="auto": the tuple of least skew near t*, waiting only while a
          camera's next frame could still be nearer to t* than its newest stored one.

Per request: t* (the reply's t_request), per camera the chosen frame's capture time t_j,
eps_j = t* - t_j, eps_b = max_j t_j - min_j t_j (the skew), tau_w_j = the moment the service
stopped waiting for camera j (timing.cameras[j].waited) - the moment it received the request.
eps'_b is eps_b over the requests whose eps_b < mean(eps_b) of that policy (paper eq. 7,
g(T) = mean). Table II is printed per policy and path next to the paper's published numbers.

Spikes. min_allowed_skew is the smallest skew the camera timing allows at all: the shortest
arc of the circle of one frame period (tau_ia = 1/fps) that covers every camera's configured
phase (phase_ms mod tau_ia), with nothing added for jitter. E.g. phases 0,1 at 20 fps: 1 ms;
phases 0,10,30: 30 ms. It uses the configured --phases, not measured frame times (the
phases observed in the replies are printed as a cross-check). A request is a spike when
eps_b > min_allowed_skew + 2 ms.

Targets, checked on our policy over each path (PASS/FAIL lines; also shown for the paper's
for reference):
  (a) no spikes: eps_b <= min_allowed_skew + 2 ms for every request;
  (b) mean tau_w over all cameras and requests <= tau_ia/8 + 1 ms + 2 standard errors of the
      mean from the random t* alone (about 0.9 ms each for 100 requests) + the machine's mean
      wake-up delay (how late the bench's sleeps before the requests ended: a loaded machine
      wakes the service late, whatever its policy; tens of us on an idle one);
  (c) max |eps_j| <= tau_ia/2 + min_allowed_skew + 2 ms.

Then, with the local path among --paths, the local waits (bench/latency/wake.py):
--wake-requests requests of each kind that wait (wait="next"; t* slightly in the future),
copied and zero-copy, timed from the storage of the frame waited for (its t_stored) to the
local client's return; targets median <= 0.5 ms, p99 <= 2 ms for the path itself, plus what
this machine takes that is not the path's, measured in the same run and shown beside each
limit: the copy of the tuple's pixels (copied replies) and the scheduler's wake-up delay (median,
p99, at the moments frames are stored). bench/latency_wake.py says why. The last line is the
verdict.

Writes latency.json (every request: times, timing record, frames, metrics; the summary) and
figures like the paper's: latency_fig5_eps.png (eps_j per request), latency_fig6_skew.png
(eps_b per request, every series), latency_fig7_spike.png (frame times around the request
with the largest eps_b of each series, chosen frames highlighted; the neighbouring frames are
fetched from the service right after such a request) and latency_fig8_wait.png (tau_w).

Exit status: 0 when the run completed (whatever the targets say); 1 if a request failed or
with --strict if a target failed; 2 on bad flags.

The pieces: experiment.py (the experiment, Table II, targets), wake.py (the local
waits), figures.py (the figures).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time

if not __package__:  # run as a script (python bench/latency/paper.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.latency import wake
from bench.latency.experiment import (
    COLUMNS,
    PAPER_TABLE_II,
    PATHS,
    POLICIES,
    Experiment,
    by_series,
    check_targets,
    format_table_ii,
    format_targets,
    label,
    observed_phases,
    parse_paths,
    parse_phases,
    parse_policies,
    policy_rows,
    run,
    series_of,
)
from bench.latency.figures import figures
from bench.shared import common
from fxis_shm import Client

# ---- command line ----------------------------------------------------------------------------


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    p.add_argument(
        "-n", "--requests", type=common.positive_int, default=100, help="requests per policy (the paper: 100)"
    )
    p.add_argument(
        "--sleep-ms",
        type=common.nonnegative_float,
        default=180.0,
        help="tau_sleep: basic sleep before each request, ms",
    )
    p.add_argument(
        "--fluct-ms",
        type=common.nonnegative_float,
        default=50.0,
        help="tau_mf: the sleep varies uniformly by +/- this, ms",
    )
    p.add_argument(
        "--policies",
        type=parse_policies,
        default=",".join(POLICIES),
        help="comma list of paper, ours (or 'both'); run interleaved in this order",
    )
    p.add_argument(
        "--paths",
        type=parse_paths,
        default=",".join(PATHS),
        help="comma list of network, local (or 'both'): the transports every policy is run over",
    )
    p.add_argument(
        "--wake-requests",
        type=int,
        default=25,
        metavar="N",
        help="local waits: requests of each kind (next, future) x (copied, zero-copy); "
        "0: not measured (nor without the local path)",
    )
    p.add_argument("--strict", action="store_true", help="exit 1 if a target fails on our policy or on the local waits")
    cams = p.add_argument_group("cameras (with --endpoint they must describe the running service)")
    cams.add_argument(
        "--cameras",
        type=common.positive_int,
        default=None,
        help="number of synthetic cameras cam0, cam1, ... (default: 2, or as many as --phases lists)",
    )
    cams.add_argument("--fps", type=common.positive_float, default=20.0, help="frame rate of every camera")
    cams.add_argument(
        "--phases",
        type=parse_phases,
        default=None,
        help="comma list of phase_ms per camera (default: 0,1 for two cameras; 0,1,...,N-1 for N)",
    )
    cams.add_argument(
        "--jitter-ms",
        type=common.nonnegative_float,
        default=0.3,
        help="uniform capture-time jitter +/- ms of every camera",
    )
    common.add_frame_size_args(cams, 1360, 1024)
    cams.add_argument("--slots", type=common.positive_int, default=20, help="frames per camera ring")
    common.add_service_args(
        p, "--fps and --phases must then describe it: the cameras' count and fps are checked against its status"
    )
    return p


# ---- main -----------------------------------------------------------------------------------


def _service_cameras(status: dict, args, names: list[str]) -> str | None:
    """Why the running service does not match the flags, or None."""
    cams = status["cameras"]
    if sorted(cams) != sorted(names):
        return (
            f"the service has cameras {sorted(cams)}, the flags describe {names}; pass "
            f"--cameras/--phases to match (this bench expects cameras named cam0, cam1, ...)"
        )
    for name, cam in cams.items():
        fps = cam.get("fps")
        if fps and abs(fps - args.fps) > 0.02 * args.fps:
            return f"camera {name} runs at {fps} fps, not --fps {args.fps:g}"
    return None


def print_targets(series: list[tuple[str, str]], summary: dict) -> bool:
    """Prints the targets of every series, ours first; True if one of ours did not pass."""
    ours = [s for s in series if s[0] == "ours"]
    for title, chosen in (
        ("targets, checked on our policy (sync=joint, wait=auto):", ours),
        ("for reference, the same targets on the paper's policy:", [s for s in series if s[0] == "paper"]),
    ):
        if chosen:
            print(title)
        for ser in chosen:
            for line in format_targets(label(ser), summary[label(ser)]["targets"]):
                print("  " + line)
    return any(t["passed"] is not True for s in ours for t in summary[label(s)]["targets"])


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
    run_args = common.synthetic_camera_flags(names, args.fps, args.width, args.height, phases, args.jitter_ms) + [
        "--slots",
        str(args.slots),
    ]
    started = time.time()
    load_at_start = os.getloadavg()
    host = common.host_info()  # before the service starts: the code it runs
    try:
        with common.service(args.endpoint, run_args, os.path.join(out, "latency.service.log"), args.timeout) as (
            client,
            info,
        ):
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
            with contextlib.ExitStack() as stack:
                clients = {
                    path: stack.enter_context(Client(info["endpoint"], timeout=args.timeout, local=PATHS[path]))
                    for path in args.paths
                }
                records = run(args, clients, exp, kinds_of, offset_ns, delay_ns)
                waits = (
                    wake.run(args, clients["local"], names, exp.period_ns)
                    if "local" in clients and args.wake_requests > 0
                    else []
                )
            status_after = client.status()
    except RuntimeError as exc:
        print(f"latency: {exc}", file=sys.stderr)
        return common.EXIT_FAILED

    series = series_of(args.policies, args.paths)
    by = by_series(records, series)
    failed = [r for r in records if r["error"] is not None] + [r for r in waits if r["error"] is not None]
    bad_stamps = sum(1 for r in records for f in r.get("frames", {}).values() if f["stamp_ok"] is False)
    phases_seen = observed_phases(records, exp)
    cam0 = status["cameras"][names[0]]
    subtitle = (
        f"{n_cams} cameras {cam0['shape'][1]}x{cam0['shape'][0]} at {args.fps:g} fps, phases "
        f"{','.join(f'{x:g}' for x in phases)} ms, jitter +/-{args.jitter_ms:g} ms, "
        f"{cam0.get('ring_slots')} slots; sleeps {args.sleep_ms:g} +/- {args.fluct_ms:g} ms"
    )
    print(
        f"latency: {subtitle}; {args.requests} requests per policy and path, interleaved "
        f"({' / '.join(map(label, series))}); seed {args.seed}"
    )
    print(common.code_line(host["code"]))
    print(
        f"tau_ia = {exp.period_ms:.2f} ms; min_allowed_skew = {exp.min_allowed_skew_ms:.2f} ms "
        f"(shortest arc covering the configured phases mod tau_ia); spike: eps_b > "
        f"{exp.spike_threshold_ms:.2f} ms"
    )
    if phases_seen:
        rel = ", ".join(f"{cam} {v:.2f}" for cam, v in phases_seen["relative_ms"].items())
        print(
            f"observed phases relative to {names[0]} (ms, circular mean of capture times mod tau_ia): "
            f"{rel}; covering arc {phases_seen['min_covering_arc_ms']:.2f} ms"
        )
        off = {c: d for c, d in phases_seen["difference_ms"].items() if d > 1.0}
        if off:
            print(
                "WARNING: observed phases differ from --phases by more than 1 ms: "
                + ", ".join(f"{cam} by {d:.2f} ms" for cam, d in off.items())
            )

    summary = {}
    for ser in series:
        recs = by[ser]
        rows = policy_rows(recs, exp)
        summary[label(ser)] = {
            "policy": ser[0],
            "path": ser[1],
            "requests": len(recs),
            "failed": sum((r.get("policy"), r.get("path")) == ser for r in failed),
            "not_by_path": sum(r["came_by"] != ser[1] for r in recs),
            "spikes": sum(r["spike"] for r in recs),
            "mean_eps_b_ms_for_eps_prime": rows["eps_b"]["mean"],
            "table_ii_ms": rows,
            "targets": check_targets(recs, exp),
            "rtt_ms": common.summary([r["rtt_ms"] for r in recs]),
        }
        print()
        print(format_table_ii(ser, rows, exp, len(recs)))
        print(
            f"spikes ({label(ser)}): {summary[label(ser)]['spikes']} of {len(recs)} requests with eps_b > "
            f"{exp.spike_threshold_ms:.2f} ms"
        )
        if summary[label(ser)]["not_by_path"]:
            print(f"WARNING: {summary[label(ser)]['not_by_path']} replies did not come by the {ser[1]} path")

    print()
    strict_failed = print_targets(series, summary)
    wait_summary = wake.summarize(waits) if waits else None
    wait_targets = wake.targets(wait_summary) if waits else []
    if waits:
        print()
        print(wake.report(wait_summary, wait_targets))
        strict_failed = strict_failed or any(t["passed"] is not True for t in wait_targets)
    print(f"failed requests: {len(failed)}; frames whose pixel stamp did not match their id: {bad_stamps}")
    for r in failed[:10]:
        what = f"request {r['i']} ({r['policy']}, {r['path']})" if "policy" in r else f"local wait ({r['kind']})"
        print(f"  failed: {what}: {r['error']}")

    json_path = os.path.join(out, "latency.json")
    common.write_json(
        json_path,
        {
            **common.run_record("latency", started, argv, args),
            "experiment": exp.as_dict(),
            "policies": {pol: POLICIES[pol] for pol in args.policies},
            "paths": {path: f"Client(local={PATHS[path]!r})" for path in args.paths},
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
            "local_waits": {
                "summary": wait_summary,
                "targets": wait_targets,
                "records": waits,
                "definition": "wake_ms = t_return - t_stored of the last returned frame stored "
                "after t_send, for requests that waited",
            },
            "failed": len(failed),
            "stamp_mismatches": bad_stamps,
            "records": records,
        },
    )
    pngs = figures(records, exp, series, out, subtitle)
    print(f"wrote {json_path}, " + ", ".join(os.path.basename(x) for x in pngs))
    ours = [t for ser in series if ser[0] == "ours" for t in summary[label(ser)]["targets"]]
    print(verdict_line([*ours, *wait_targets], load_at_start, failed))
    if failed:
        return common.EXIT_FAILED
    if args.strict and strict_failed:
        return common.EXIT_FAILED
    return common.EXIT_OK


def verdict_line(targets: list[dict], load_at_start: tuple[float, ...], failed: list) -> str:
    """The demo's last line, for a newcomer: were the targets met, on what kind of machine."""
    load = f"{os.cpu_count()} cores, load average {load_at_start[0]:.1f} at the start and {os.getloadavg()[0]:.1f} now"
    missed = [t for t in targets if t["passed"] is not True]
    if failed:
        return f"verdict: {len(failed)} request(s) FAILED (listed above) ({load})"
    if not missed:
        return f"verdict: all {len(targets)} targets met ({load})"
    names = "; ".join(
        f"{t.get('text') or t['target']}: {common.fmt(t['value_ms'], 3)} ms > {common.fmt(t['limit_ms'], 3)} ms"
        for t in missed
    )
    return (
        f"verdict: {len(missed)} of {len(targets)} targets missed: {names} ({load}; a loaded or shared machine "
        "misses the tightest ones: run again on a quiet one)"
    )


if __name__ == "__main__":
    sys.exit(main())
