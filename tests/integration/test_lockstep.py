"""Lockstep (issue 34): ``fxis run --lockstep HZ[,PHASE_MS]`` triggers every camera that can be
triggered on the grid k/HZ + PHASE of CLOCK_REALTIME (or CLOCK_TAI, ``--lockstep-clock tai``),
the cell's common clock. Services on hosts
with their own CLOCK_MONOTONIC, started apart, then give joint tuples whose skew is the trigger
jitter, where the same services' free-running cameras give their phase.

No bound here is a speed: the skews are held to what the workers' timers measured of their own
lateness (status ``timer_late_*``) plus the clock estimates' uncertainty. bench/sync/ measures."""

import statistics
import time

import pytest

from fxis_shm import Client
from fxis_shm.core import timebase
from fxis_shm.core.requestdefaults import REQUEST_DEFAULTS

from ..conftest import fxis, wait_until
from .conftest import SMALL

# residuals and skews of real timers: the real-time tier, its services at SCHED_FIFO (--realtime), as a cell
# that needs its cameras in step runs them
pytestmark = [pytest.mark.integration, pytest.mark.realtime]

MS = 1_000_000
HZ = 20
PERIOD_NS = 10**9 // HZ
LATENCY_NOISE_NS = MS // 2  # what a learned trigger latency may miss by (tests/integration/test_capture_at.py)
TRIGGERED = f"synthetic:trigger=software,trigger_latency_ms=3,{SMALL}"
MARGIN_NS = 500_000  # beyond a clock estimate's stated uncertainty (tests/integration/test_hosts.py)
# tuples this much more skewed than the least count as equally synchronized (the services here keep the default)
SYNC_TOLERANCE_NS = int(REQUEST_DEFAULTS["sync_tolerance_ms"] * MS)


# (the kernel's TAI offset is 0 unless ptp4l or chrony set it: then both grids are one here, and
# tests/unit/test_schedule.py holds the tai grid apart from the realtime one)
@pytest.mark.parametrize("clock", ["realtime", "tai"])
def test_a_lockstep_camera_captures_on_the_grid_of_its_clock_and_says_so(start_service, clock):
    svc = start_service(
        "--realtime", "--lockstep", f"{HZ},5", "--lockstep-clock", clock, "--camera", f"trig={TRIGGERED}"
    )
    with svc.client() as client:
        wait_until(lambda: client.status()["cameras"]["trig"]["frames_stored"] >= 20, what="a second of frames")
        frames = [client.tuple(["trig"]).values() for _ in range(5)]  # no extra trigger: the grid's frames
        status = client.status()["cameras"]["trig"]
    shown = fxis("status", "--endpoint", svc.endpoint).stdout
    assert "trig: trigger latency" in shown and f"lockstep 20 Hz + 5 ms of CLOCK_{clock.upper()}" in shown
    sync = status["sync"]
    assert status["trigger"] == "free"  # its frames come on their own: a request does not trigger it
    assert sync["lockstep"]["hz"] == HZ and sync["lockstep"]["phase_ms"] == 5.0
    assert sync["lockstep"]["clock"] == f"CLOCK_{clock.upper()}"  # the one spelling of every reply
    assert sync["lockstep"]["frames"] >= 20
    assert (
        -LATENCY_NOISE_NS
        <= sync["lockstep"]["residual_p50_ms"] * MS
        <= sync["timer_late_p50_ms"] * MS + LATENCY_NOISE_NS
    )
    offset = timebase.offset(clock, "monotonic")  # the service's clock is this host's CLOCK_MONOTONIC
    for (frame,) in frames:
        assert frame.capture == "lockstep"
        on_grid = (frame.t_target + offset - 5 * MS) % PERIOD_NS
        assert min(on_grid, PERIOD_NS - on_grid) <= 100_000  # the clocks' offset, read twice
        assert frame.residual_ns >= -LATENCY_NOISE_NS  # never early (late: the timer's lateness, above)


def test_lockstep_across_hosts_skews_by_the_trigger_jitter_not_by_the_phase(emulated_hosts):
    hosts = [emulated_hosts.host(clock_offset_s=1000), emulated_hosts.host(clock_offset_s=2000)]
    services = []
    for host, side in zip(hosts, ("l", "r")):
        services.append(
            host.service(
                "--realtime",
                "--lockstep",
                str(HZ),
                "--camera",
                f"{side}trig={TRIGGERED}",
                "--camera",
                f"{side}free=synthetic:fps={HZ},{SMALL}",
            )
        )
        time.sleep(0.017)  # started apart: their free cameras' phases differ by whatever this makes
    endpoints = [svc.endpoint for svc in services]
    with Client(endpoints, timeout=15.0, keys=emulated_hosts.client_keys) as client:

        def estimated():
            estimates = [client.clocks.get(e) for e in endpoints]
            return all(e is not None and e.method == "estimated" for e in estimates) and estimates

        wait_until(estimated, timeout=30, what="clock estimates for both hosts")
        wait_until(lambda: all(c["frames_stored"] >= 20 for c in client.status()["cameras"].values()), timeout=30)
        pairs = []
        for _ in range(30):
            at = time.monotonic_ns() - 200 * MS  # stored frames: no waiting
            pairs.append((client.tuple(["ltrig", "rtrig"], at=at), client.tuple(["lfree", "rfree"], at=at)))
            time.sleep(0.03)
        syncs = [client.status()["cameras"][name]["sync"] for name in ("ltrig", "rtrig")]
        estimates = [client.clocks[e] for e in endpoints]
    uncertainty = sum(e.uncertainty_ns for e in estimates) + 2 * MARGIN_NS

    def true_skew(pair) -> int:
        left, right = pair.values()
        return abs(
            (left.service_t_capture - hosts[0].clock_offset_ns) - (right.service_t_capture - hosts[1].clock_offset_ns)
        )

    lockstep = [true_skew(trig) for trig, _ in pairs]
    free = [true_skew(free) for _, free in pairs]
    for trig, _ in pairs:
        left, right = trig.values()
        assert left.capture == right.capture == "lockstep"
        assert abs(left.t_target - right.t_target) <= uncertainty  # one grid point, seen from two clocks
    # the free cameras: their phase p, the same in every tuple (a camera's jitter is 0 here). With p within the
    # sync tolerance of half a period, pairing each frame with the other camera's next one (skew period - p) is
    # as synchronized by the service's rule, and the pairing nearer t* is chosen (core.selection.select_joint)
    phase = statistics.median(min(s, PERIOD_NS - s) for s in free)
    pairings = [phase] + ([PERIOD_NS - phase] if PERIOD_NS - 2 * phase <= SYNC_TOLERANCE_NS + uncertainty else [])
    skews_ms = [round(s / MS, 3) for s in free]
    assert all(any(abs(s - p) <= uncertainty for p in pairings) for s in free), (skews_ms, uncertainty)
    # lockstep: the two timers' lateness and the latencies' noise, whatever the phase (two frames
    # of one grid point are apart by at most the sum of their triggers' lateness)
    late_p99 = sum(s["timer_late_p99_ms"] for s in syncs) * MS
    within = sum(s <= late_p99 + 2 * LATENCY_NOISE_NS for s in lockstep)
    assert within >= 0.9 * len(lockstep), (lockstep, late_p99)
    if phase > late_p99 + 2 * LATENCY_NOISE_NS + uncertainty:  # (17 ms apart, unless the origins met)
        assert statistics.median(lockstep) < phase
