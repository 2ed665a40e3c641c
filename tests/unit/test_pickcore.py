"""pickcore (fxis_shm/core/pickcore.c), the C twin of the decision of image and tuple requests
(``_near`` in fxis_shm.core.decisions), decides as the Python does.

Hypothesis draws the cameras (random names, so that their order by name differs from the
request's; timelines with ties, jitter, dropped frames and realtime magnitudes; measured or
unknown periods; delays), the clocks (t* before, among and after the frames; now, also at the
nanosecond a coming frame counts as dropped) and the requests (image or tuple, joint or
independent, wait auto or none, ``at`` or not, sync tolerances, max skews). On every case both
plan the same frame per camera with the same skew, wait for the same cameras, or reject with the
same code; within its caps the C never gives up (UNSUPPORTED). Two more properties aim at what
random cases seldom reach: synchronized cameras (ties across cameras, broken by name), and sync
tolerances and max skews right at the skews that decide between tuples. The examples pin the
tricky spots one by one, and the caps.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import combinations
from random import Random

import pytest
from hypothesis import event, given, settings, strategies as st

from fxis_shm.core.decisions import Context, Reject, Wait, decide
from fxis_shm.core.engine import Pending
from fxis_shm.core.requeststate import MOVES, WAITING
from fxis_shm.core.snapshot import CAPTURE_LOCKSTEP as LOCKSTEP, SlotMeta, Snapshot
from fxis_shm.core.waitpolicy import CameraState

from ..virtualtime.cell import TWIN_STATES
from .timeline_helpers import brute_nearest, ring

# _fastpick imported directly, so that FXIS_PURE_PYTHON=1 (the Python decision then runs as its
# source, not compiled) still compares the two. Not built is a failure, as in test_slotio.py.
try:
    from fxis_shm.shm import _fastpick
except ImportError as not_built:
    raise ImportError(f"fxis_shm.shm._fastpick is not built ({not_built}): `make setup` builds it") from not_built

PLAN, WAIT, REJECT, UNSUPPORTED = _fastpick.PLAN, _fastpick.WAIT, _fastpick.REJECT, _fastpick.UNSUPPORTED
SPARE_SLOTS = 3  # the Python reads each timeline from a ring this much larger, wrapped around


@dataclass(frozen=True)
class Camera:
    name: str
    times: tuple[int, ...]  # capture times of the stored frames, oldest first
    period_ns: int = 100  # as measured; 0: not known yet (100: the examples' frame period)
    delay_ns: int = 0  # capture to storage
    grid: tuple[int, ...] | None = None  # per frame: its lockstep grid point (t_target), 0 if not lockstep


@dataclass(frozen=True)
class Case:
    """One request at one moment, over the cameras' stored frames."""

    cameras: tuple[Camera, ...]  # in the request's order
    t_star: int
    now: int
    op: str = "tuple"
    sync: str = "joint"
    wait: str = "none"
    at_given: bool = False  # `at` was given: a t* older than the rings is OUT_OF_RANGE
    sync_tolerance_ms: float = 0.0
    max_skew_ms: float | None = None
    ring_start: int = 0  # where the Python's rings hold their oldest frame (the C reads plain lists)


# A decision, alike for both: (PLAN, index per camera, skew_ns), (WAIT, positions of the waited
# cameras in the request, ascending) or (REJECT, error code); the C may also say (UNSUPPORTED, None).


def c_decision(case: Case) -> tuple:
    ranks = {name: rank for rank, name in enumerate(sorted(c.name for c in case.cameras))}
    return _fastpick.decide_near(
        [
            (list(c.times), ranks[c.name], c.period_ns, c.delay_ns, *([list(c.grid)] if c.grid else []))
            for c in case.cameras
        ],
        case.t_star,
        case.now,
        int(case.op == "tuple"),
        int(case.sync == "joint"),
        int(case.wait == "auto"),
        int(case.at_given),
        int(case.sync_tolerance_ms * 1e6),
        -1.0 if case.max_skew_ms is None else case.max_skew_ms * 1e6,
    )


def python_snapshot(camera: Camera, ring_start: int) -> Snapshot:
    slots = len(camera.times) + SPARE_SLOTS
    rows: list[SlotMeta | None] = [None] * slots  # without a grid: never read
    for i, point in enumerate(camera.grid or ()):
        rows[(ring_start + i) % slots] = SlotMeta(
            i, camera.times[i], camera.times[i], camera.times[i], 1, point, LOCKSTEP
        )
    return Snapshot(ring(list(camera.times), slots, ring_start), ring_start, rows)


def python_state(camera: Camera) -> CameraState:
    newest = camera.times[-1] if camera.times else None
    stored = None if newest is None else newest + camera.delay_ns
    return CameraState(newest, camera.period_ns, camera.delay_ns, stored)


def python_decision(case: Case) -> tuple:
    """The Python's decision as the C says it; a plan whose lockstep frames are of different grid
    points also says so: (PLAN, indices, skew_ns, {camera: grid point})."""
    names = [c.name for c in case.cameras]
    request = Pending(None, {"op": case.op, "at": case.t_star if case.at_given else None}, names, case.now, case.t_star)
    snaps = {c.name: python_snapshot(c, case.ring_start) for c in case.cameras}
    states = {c.name: python_state(c) for c in case.cameras}
    periods = {c.name: c.period_ns for c in case.cameras}
    context = Context(periods, case.wait, case.sync, case.sync_tolerance_ms, case.max_skew_ms, 500)
    try:
        decision = decide(request, case.now, snaps, states, context)
    except Reject as reject:
        return REJECT, reject.code
    if isinstance(decision, Wait):
        return WAIT, tuple(sorted(names.index(name) for name in decision.until))
    assert [name for name, _ in decision.picks] == names  # the frames in the order asked
    plan = PLAN, tuple(index for _, index in decision.picks), decision.body.get("skew_ns", 0)
    return (*plan, decision.body["grid_mismatch"]) if "grid_mismatch" in decision.body else plan


def decided_alike(case: Case) -> tuple:
    """The decision both make (failing if they differ): a move of the waiting request that the
    state table allows (a wait leaves it waiting)."""
    in_c = c_decision(case)
    assert in_c[0] != UNSUPPORTED, "pickcore gave up on a case within its caps"
    assert in_c == python_decision(case)
    assert TWIN_STATES[in_c[0]] in MOVES[WAITING] | {WAITING}
    return in_c


def decided_alike_on_grid(case: Case) -> tuple:
    """The decision both make, or the Python's where the C leaves it to the Python: a tuple whose
    lockstep frames are of different grid points (the Python then answers with a tuple of one
    point, or flags it). Off the grid, the C decides as without grid points."""
    in_c, in_python = c_decision(case), python_decision(case)
    without_grid = replace(case, cameras=tuple(replace(c, grid=None) for c in case.cameras))
    if in_c[0] != UNSUPPORTED:
        assert in_c == in_python == c_decision(without_grid)
        return in_c
    if in_python[0] == REJECT:  # a tuple of one point, more skewed than max_skew_ms allows
        assert in_python[1] == "SKEW_EXCEEDED"
    else:  # flagged, or of one grid point (the C gives up at the first tuple off the grid, before a
        # max_skew_ms choice the Python makes among tuples of one point)
        assert in_python[0] == PLAN and (len(in_python) == 4 or len(grid_points(case, in_python[1])) == 1)
    return in_python


def grid_points(case: Case, picks: tuple) -> set:
    """The grid points of the lockstep frames ``picks`` chooses (one index per camera)."""
    return {c.grid[i] for c, i in zip(case.cameras, picks) if c.grid}


# ---- the cases hypothesis draws ----------------------------------------------------------------

REALTIME_NS = 1_700_000_000_000_000_000  # a CLOCK_REALTIME reading (< 2**61; differences stay < 2**52)
CAMERA_NAMES = st.text("abcxyz", min_size=1, max_size=3)
FRAME_SPACINGS = st.one_of(st.integers(1_000, 100_000_000), st.sampled_from([1_000, 10_000_000, 33_333_333]))
SPACING_RATIOS = (1.0, 1.0, 1.0, 1.0001, 1.2, 0.5, 2.0)  # a camera's frame spacing to the case's
GRID_STEPS = (1, 1, 1, 1, 0, 2, 3)  # from one frame to the next: mostly one period; ties; dropped frames
TOLERANCE_FACTORS = (0.0, 0.5, 1.0, 2.0, 5.0)  # sync_tolerance_ms, in "ms" scaled to the frame spacing


FREE_RUNNING, STEADY, SYNCHRONIZED = "free-running", "steady", "synchronized"  # kinds of camera sets


@st.composite
def camera_frames(draw, case_spacing: int, kind: str, noise: Random) -> tuple[list[int], int]:
    """Capture times (from the case's origin) of a camera, and its frame spacing: free-running
    cameras have their own spacing, phase and jitter; steady ones share the spacing, with little
    jitter; synchronized ones are triggered by one pulse train (some at every other pulse, some
    at twice its rate), at equal times."""
    spacing, phase, jitter = case_spacing, 0, 0
    if kind == FREE_RUNNING:
        spacing = min(100_000_000, max(1_000, int(case_spacing * draw(st.sampled_from(SPACING_RATIOS)))))
        jitter = draw(st.sampled_from([0, spacing // 100, spacing // 10, spacing // 3]))
    elif kind == STEADY:
        jitter = draw(st.sampled_from([spacing // 1000, spacing // 100]))
    else:
        spacing = case_spacing * draw(st.sampled_from([2, 2, 1, 4])) // 2
    if kind != SYNCHRONIZED and draw(st.booleans()):
        phase = noise.randint(-spacing, spacing)
    if kind == STEADY:  # running for a while, all of them
        stored, grid = draw(st.integers(8, 40)), 0
    else:  # now and then a camera that stored nothing yet; some started late (on the grid)
        stored = 0 if draw(st.integers(0, 19)) == 0 else draw(st.integers(1, 40))
        grid = draw(st.integers(0, 5))
    times: list[int] = []
    for step in draw(st.lists(st.sampled_from(GRID_STEPS), min_size=stored, max_size=stored)):
        times.append(max(phase + grid * spacing + noise.randint(-jitter, jitter), times[-1] if times else -(2**62)))
        grid += step
    return times, spacing


ANY, SYNCHRONIZED_TUPLES, AT_THE_BOUNDARIES = "any", "synchronized tuples", "at the boundaries"  # cases' focus


@st.composite
def cases(draw, focus: str = ANY) -> Case:
    """Any request of the C's kinds; or, with t* among the frames, joint tuples of one of these:
    SYNCHRONIZED_TUPLES: 3 to 5 synchronized cameras (equal times: ties broken by name);
    AT_THE_BOUNDARIES: 2 or 3 steady cameras, the sync tolerance and the max skew at the skews
    (and differences of skews) that decide between the tuples about t*."""
    op = "tuple" if focus != ANY else draw(st.sampled_from(["tuple", "tuple", "image"]))
    fewest, most = {ANY: (1, 1 if op == "image" else 5), SYNCHRONIZED_TUPLES: (3, 5), AT_THE_BOUNDARIES: (2, 3)}[focus]
    names = draw(st.lists(CAMERA_NAMES, min_size=fewest, max_size=most, unique=True))
    case_spacing = draw(FRAME_SPACINGS)
    origin = draw(st.sampled_from([0, REALTIME_NS])) + draw(st.integers(0, 10**9))
    noise = draw(st.randoms())  # phases and jitter, drawn (and shrunk, and replayed) by hypothesis
    kinds = {ANY: [FREE_RUNNING, FREE_RUNNING, STEADY, SYNCHRONIZED], SYNCHRONIZED_TUPLES: [SYNCHRONIZED]}
    kind = draw(st.sampled_from(kinds.get(focus, [STEADY])))
    cameras, spacings = [], []
    for name in names:
        times, spacing = draw(camera_frames(case_spacing, kind, noise))
        spacings.append(spacing)
        measured = [st.just(spacing), st.integers(spacing - spacing // 50, spacing + spacing // 50)]
        unknown = [] if kind == STEADY else [st.just(0)]
        cameras.append(
            Camera(
                name,
                tuple(origin + t for t in times),
                period_ns=draw(st.one_of(*measured, *unknown)),
                delay_ns=draw(st.one_of(st.just(0), st.integers(0, 2 * spacing))),
            )
        )
    longest = max(spacings)
    t_star = draw(t_stars(cameras, origin, longest, noise, among_frames=focus != ANY))
    skews = skews_near(cameras, t_star, longest)
    tolerance_unit_ns = draw(st.sampled_from([longest // 33, 10**6]))  # 1 "ms" of a 33 ms period, or 1 ms
    tolerances = st.sampled_from([factor * tolerance_unit_ns for factor in TOLERANCE_FACTORS])
    max_skews = st.sampled_from(skews)
    if focus == AT_THE_BOUNDARIES:
        tolerances |= st.sampled_from(sorted({b - a - d for a in skews for b in skews if a < b for d in (0, 1)}))
        max_skews = st.sampled_from(sorted({max(0, s - d) for s in skews for d in (0, 1)}))
    max_skew_ns = draw(st.none() | max_skews)
    return Case(
        tuple(cameras),
        t_star,
        now=draw(nows(cameras, origin, t_star, longest)),
        op=op,
        sync="joint" if focus != ANY else draw(st.sampled_from(["joint", "independent"])),
        wait=draw(st.sampled_from(["auto", "none"])),
        at_given=draw(st.booleans()),
        sync_tolerance_ms=draw(tolerances) / 1e6,
        max_skew_ms=None if max_skew_ns is None else max_skew_ns / 1e6,
        ring_start=draw(st.integers(0, 50)),
    )


def t_stars(
    cameras: list[Camera], origin: int, longest: int, noise: Random, among_frames: bool
) -> st.SearchStrategy[int]:
    """Among the frames: on a frame, halfway between two (or a nanosecond either side), or
    anywhere between the oldest and the newest; unless ``among_frames``, also from well before
    the oldest frame to well after the newest, and near the newest."""
    every_time = sorted(t for c in cameras for t in c.times)
    oldest, newest = (every_time[0], every_time[-1]) if every_time else (origin, origin)
    t_star = st.integers(oldest, newest) | st.just(noise.randint(oldest, newest))
    if not among_frames:
        before_to_after = st.integers(oldest - 3 * longest, newest + 8 * longest)
        t_star |= before_to_after | st.integers(newest - 2 * longest, newest + 2 * longest)
    if len(every_time) >= 2:
        halfway = [(a + b) // 2 for a, b in zip(every_time, every_time[1:])]
        t_star |= st.sampled_from(every_time) | st.builds(int.__add__, st.sampled_from(halfway), st.integers(-1, 1))
    return t_star


def nows(cameras: list[Camera], origin: int, t_star: int, longest: int) -> st.SearchStrategy[int]:
    """From a period before the newest frame to 6 after it; or at (or a nanosecond before) the
    moment a camera's coming frame nearest t* counts as dropped."""
    newest = max([origin, *(t for c in cameras for t in c.times)])
    dropped_at = []
    for c in cameras:
        if c.times and c.period_ns > 0:
            coming = max(1, round((t_star - c.times[-1]) / c.period_ns))  # the coming frame nearest t*
            dropped_at += [
                c.times[-1] + k * c.period_ns + c.period_ns + c.delay_ns - d
                for k in (coming, coming + 1)
                for d in (0, 1)
            ]
    around_newest = st.integers(newest - longest, newest + 6 * longest)
    return around_newest | st.sampled_from(dropped_at) if dropped_at else around_newest


def skews_near(cameras: list[Camera], t_star: int, longest: int) -> list[int]:
    """The skews of tuples near t* (and a nanosecond more), in ns: of each camera's nearest
    frames, and the distances between two cameras' frames near t*; and 0."""
    nearest = [c.times[brute_nearest(c.times, t_star)] for c in cameras if c.times]
    skew = max(nearest) - min(nearest) if nearest else 0
    near = [[t for t in c.times if abs(t - t_star) <= longest] for c in cameras]
    apart = {abs(a - b) for one, other in combinations(near, 2) for a in one for b in other}
    return sorted({0, skew, skew + 1, longest // 4, *apart})


def outcome(decision: tuple) -> str:
    return {PLAN: "plan", WAIT: "wait"}.get(decision[0]) or f"reject {decision[1]}"


@settings(max_examples=400, deadline=None)
@given(cases())
def test_c_and_python_decide_alike(case):
    event(outcome(decided_alike(case)))


@settings(max_examples=200, deadline=None)
@given(cases(SYNCHRONIZED_TUPLES))
def test_c_and_python_decide_alike_on_synchronized_cameras(case):
    event(outcome(decided_alike(case)))


@settings(max_examples=300, deadline=None)
@given(cases(AT_THE_BOUNDARIES))
def test_c_and_python_decide_alike_at_the_tolerance_and_max_skew_boundaries(case):
    event(outcome(decided_alike(case)))


@st.composite
def lockstep_cases(draw) -> Case:
    """Synchronized cameras on one lockstep grid (each frame's grid point its pulse's time), some
    frames captured late (by up to 80 % of the spacing), now and then a camera free-running."""
    case = draw(cases(SYNCHRONIZED_TUPLES))
    cameras = []
    for camera in case.cameras:
        if not camera.times or draw(st.integers(0, 4)) == 0:
            cameras.append(camera)
            continue
        spacing = max(1, camera.period_ns)
        late, times = (
            draw(
                st.lists(
                    st.sampled_from([0, 0, 0, 1, spacing // 3, spacing * 4 // 5]),
                    min_size=len(camera.times),
                    max_size=len(camera.times),
                )
            ),
            [],
        )
        for t, lateness in zip(camera.times, late):
            times.append(max(t + lateness, times[-1] if times else t))
        cameras.append(replace(camera, times=tuple(times), grid=camera.times))
    return replace(case, cameras=tuple(cameras))


@settings(max_examples=200, deadline=None)
@given(lockstep_cases())
def test_c_and_python_decide_alike_on_lockstep_cameras_or_the_c_leaves_it_off_the_grid(case):
    decision = decided_alike_on_grid(case)
    event(outcome(decision) + (" off the grid" if len(decision) == 4 or c_decision(case)[0] == UNSUPPORTED else ""))


# ---- the tricky spots ------------------------------------------------------------------------


def test_t_star_halfway_between_frames_takes_the_newer():
    case = Case((Camera("a", (0, 100)),), t_star=50, now=1000, op="image")
    assert decided_alike(case) == (PLAN, (1,), 0)


def test_equal_capture_times_go_by_camera_name_not_by_request_order():
    # c's and a's frames at 100 tie; in name order (a first) the least-skew window ends at a's 150
    cameras = (Camera("c", (100,)), Camera("b", (200,)), Camera("a", (100, 150)))
    assert decided_alike(Case(cameras, t_star=100, now=1000)) == (PLAN, (0, 0, 1), 100)


def test_a_joint_tuple_does_not_spike_where_the_independent_one_does():
    cameras = (Camera("a", (0, 100, 200)), Camera("b", (2, 102, 202)))
    assert decided_alike(Case(cameras, t_star=51, now=1000, sync="independent")) == (PLAN, (1, 0), 98)
    assert decided_alike(Case(cameras, t_star=51, now=1000, sync="joint")) == (PLAN, (1, 1), 2)


# b's frame at 300 is stored, a's is coming (it counts as dropped from 300 + period + delay on)
LATE_A = (Camera("b", (0, 100, 200, 300), delay_ns=5), Camera("a", (0, 100, 200), delay_ns=5))


def test_wait_auto_waits_for_the_camera_whose_frame_is_coming():
    assert decided_alike(Case(LATE_A, t_star=290, now=310, wait="auto")) == (WAIT, (1,))
    assert decided_alike(Case(LATE_A, t_star=290, now=404, wait="auto")) == (WAIT, (1,))


def test_an_overdue_frame_is_taken_as_dropped():
    assert decided_alike(Case(LATE_A, t_star=290, now=405, wait="auto", sync="independent")) == (PLAN, (3, 2), 100)


def test_a_camera_without_frames():
    cameras = (Camera("a", (0, 100)), Camera("b", ()))
    assert decided_alike(Case(cameras, t_star=50, now=1000, wait="none")) == (REJECT, "NO_FRAMES")
    assert decided_alike(Case(cameras, t_star=50, now=1000, wait="auto")) == (WAIT, (1,))


def test_a_t_star_older_than_the_ring_by_more_than_half_a_period_is_out_of_range_when_at_is_given():
    # the frame nearest 949 (at 900) was overwritten: the oldest held (1000) is not it
    cameras = (Camera("a", (1000, 1100)),)
    assert decided_alike(Case(cameras, t_star=949, now=2000, at_given=True)) == (REJECT, "OUT_OF_RANGE")
    assert decided_alike(Case(cameras, t_star=950, now=2000, at_given=True)) == (PLAN, (0,), 0)
    assert decided_alike(Case(cameras, t_star=949, now=2000, at_given=False)) == (PLAN, (0,), 0)
    odd = (Camera("a", (1000, 1101), period_ns=101),)  # half of 101 ns: 50.5
    assert decided_alike(Case(odd, t_star=950, now=2000, at_given=True)) == (PLAN, (0,), 0)
    assert decided_alike(Case(odd, t_star=949, now=2000, at_given=True)) == (REJECT, "OUT_OF_RANGE")


# the case of issue 41 (tests/unit/test_selection.py), in units of 0.1 ms: lockstep grid points
# at 10000, 10500, 11000, 11500; left and right captured 10000 1.52 and 1.57 ms late, right missed two
ISSUE_41 = (
    Camera("left", (10152, 10500, 11000), period_ns=500, grid=(10000, 10500, 11000)),
    Camera("right", (10157, 11500), period_ns=500, grid=(10000, 11500)),
)


def test_the_tuple_of_one_grid_point_hidden_by_the_window_is_chosen_by_both():
    assert decided_alike(Case(ISSUE_41, t_star=10700, now=20000)) == (PLAN, (0, 0), 5)


def test_lockstep_frames_of_different_grid_points_are_left_to_the_python_which_flags_them():
    # right's frame of 10000 was captured late, 3.5 ms after left's of 10500: the least skew pairs
    # two grid points, and no point near t* has a frame of both (left dropped 10000)
    cameras = (
        Camera("left", (10500, 11000), period_ns=500, grid=(10500, 11000)),
        Camera("right", (10465, 11500), period_ns=500, grid=(10000, 11500)),
    )
    case = Case(cameras, t_star=10500, now=20000)
    assert c_decision(case) == (UNSUPPORTED, None)
    assert python_decision(case) == (PLAN, (0, 0), 35, {"left": 10500, "right": 10000})
    on_one_point = (cameras[0], replace(cameras[1], grid=(10500, 11500)))  # had it been captured early for 10500
    assert decided_alike(replace(case, cameras=on_one_point)) == (PLAN, (0, 0), 35)


def test_a_tuple_of_one_grid_point_is_preferred_to_a_less_skewed_one_of_two():
    # right's frame of 10000 captured 3.5 ms late pairs best with left's of 10500 (skew 0.35 ms),
    # but left's frame of 10000 is stored: the tuple of one point (skew 4.65 ms... ) wins
    cameras = (
        Camera("left", (10000, 10500, 11000), period_ns=500, grid=(10000, 10500, 11000)),
        Camera("right", (10465, 11500), period_ns=500, grid=(10000, 11500)),
    )
    case = Case(cameras, t_star=10500, now=20000)
    assert c_decision(case) == (UNSUPPORTED, None)
    assert python_decision(case) == (PLAN, (0, 0), 465)


# ---- the tricky spots ---


def test_max_skew_rejects_or_reselects_at_zero_tolerance():
    # within the 5 ns tolerance the tuple nearest t* (skew 5) wins; under max skew 4 ns the
    # least-skew tuple (skew 3) is chosen again at tolerance 0; under 2 ns none will do
    cameras = (Camera("a", (0, 100)), Camera("b", (3, 95)))
    tolerant = Case(cameras, t_star=100, now=1000, sync_tolerance_ms=5e-6)
    assert decided_alike(tolerant) == (PLAN, (1, 1), 5)
    assert decided_alike(replace(tolerant, max_skew_ms=4e-6)) == (PLAN, (0, 0), 3)
    assert decided_alike(replace(tolerant, max_skew_ms=2e-6)) == (REJECT, "SKEW_EXCEEDED")


# ---- the caps ---------------------------------------------------------------------------------


def test_up_to_64_predicted_frames_the_c_decides_beyond_them_it_gives_up():
    # period 1 ns: frames predicted at 1 .. t* + 1 (the radius), none overdue at now 0
    def predicting(frames: int) -> Case:
        return Case((Camera("a", (0,), period_ns=1),), t_star=frames - 1, now=0, op="image", wait="auto")

    assert decided_alike(predicting(64)) == (WAIT, (0,))
    assert c_decision(predicting(65)) == (UNSUPPORTED, None)
    assert python_decision(predicting(65)) == (WAIT, (0,))


def test_up_to_4096_prediction_steps_the_c_decides_beyond_them_it_gives_up():
    # period 1 ns, every predicted frame long overdue: steps 1 .. t* + 1, none of them predicted
    def stepping(steps: int) -> Case:
        return Case((Camera("a", (0,), period_ns=1),), t_star=steps - 1, now=10**9, op="image", wait="auto")

    assert decided_alike(stepping(4096)) == (PLAN, (0,), 0)
    assert c_decision(stepping(4097)) == (UNSUPPORTED, None)
    assert python_decision(stepping(4097)) == (PLAN, (0,), 0)


def test_up_to_1024_candidate_frames_the_c_decides_beyond_them_it_gives_up():
    # a period of 1000 ns puts every frame within the radius of t*: all of them are candidates
    def candidates(b_frames: int) -> Case:
        cameras = (Camera("a", tuple(range(512)), period_ns=1000), Camera("b", tuple(range(b_frames)), period_ns=1000))
        return Case(cameras, t_star=300, now=10**9)

    assert decided_alike(candidates(512)) == (PLAN, (300, 300), 0)
    assert c_decision(candidates(513)) == (UNSUPPORTED, None)
    assert python_decision(candidates(513)) == (PLAN, (300, 300), 0)


def test_up_to_32_cameras_the_c_decides_more_its_test_entry_refuses():
    def cameras(n: int) -> tuple[Camera, ...]:
        return tuple(Camera(f"cam{k:02}", (k, 100 + k)) for k in range(n))

    assert decided_alike(Case(cameras(32), t_star=70, now=1000)) == (PLAN, (1,) * 32, 31)
    with pytest.raises(ValueError, match="1 to 32 cameras"):
        c_decision(Case(cameras(33), t_star=60, now=1000))
