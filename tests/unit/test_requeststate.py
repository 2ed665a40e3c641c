"""A request's named states (fxis_shm.core.requeststate): every allowed and every refused move of
the table, and the engine moving its requests only along it (fxis_shm.core.engine), over the
camera tables of test_engine.py."""

from __future__ import annotations

from itertools import product

import pytest

from fxis_shm.core.engine import COPY_ATTEMPTS, Failure, Pending, Reply, Schedule, Trigger
from fxis_shm.core.requeststate import MOVES, WAITING_STATES, IllegalMove, RequestState, checked_move, waiting_state

from .test_engine import DELAY, PERIOD, TableCamera, engine_with, only, request
from .timeline_helpers import MS

RECEIVED, WAITING, TRIGGERED, SCHEDULED, ANSWERED, FAILED, CANCELLED = (
    RequestState.RECEIVED,
    RequestState.WAITING,
    RequestState.TRIGGERED,
    RequestState.SCHEDULED,
    RequestState.ANSWERED,
    RequestState.FAILED,
    RequestState.CANCELLED,
)

# The table spelled out again, move by move, so that a change to MOVES must be made here too.
ALLOWED = {
    (RECEIVED, WAITING),  # admitted, waits for frames
    (RECEIVED, TRIGGERED),  # admitted, fired software triggers
    (RECEIVED, SCHEDULED),  # admitted, scheduled a capture at t*
    (RECEIVED, FAILED),  # refused at admission
    *((waiting, to) for waiting in (WAITING, TRIGGERED, SCHEDULED) for to in (ANSWERED, FAILED, CANCELLED)),
    (ANSWERED, ANSWERED),  # a copy overwritten: planned again
    (ANSWERED, WAITING),  # ... or waits again, the way it waited
    (ANSWERED, TRIGGERED),
    (ANSWERED, SCHEDULED),
    (ANSWERED, FAILED),  # ... or fails (overwritten once too often, a camera down)
}
EVERY_MOVE = sorted(product(RequestState, RequestState), key=lambda move: (move[0].value, move[1].value))


@pytest.mark.parametrize("state, to", [m for m in EVERY_MOVE if m in ALLOWED], ids=str)
def test_an_allowed_move_is_made(state, to):
    assert checked_move(state, to) is to
    p = Pending(None, {"op": "image"}, ["cam"], 0, 0, state=state)
    p.move(to)
    assert p.state is to


@pytest.mark.parametrize("state, to", [m for m in EVERY_MOVE if m not in ALLOWED], ids=str)
def test_a_refused_move_raises_and_leaves_the_state(state, to):
    p = Pending(None, {"op": "image"}, ["cam"], 0, 0, state=state)
    with pytest.raises(IllegalMove) as refused:
        p.move(to)
    assert str(refused.value) == f"a request {state.value} cannot become {to.value}"
    assert (refused.value.state, refused.value.to) == (state, to)
    assert p.state is state


def test_the_table_names_every_state_and_the_final_ones_have_no_move():
    assert set(MOVES) == set(RequestState)
    assert {s for s, moves in MOVES.items() if not moves} == {FAILED, CANCELLED}
    assert WAITING_STATES == {WAITING, TRIGGERED, SCHEDULED}


@pytest.mark.parametrize(
    "triggered, scheduled, expected",
    [((), (), WAITING), (("a",), (), TRIGGERED), ((), ("a",), SCHEDULED), (("a",), ("b",), SCHEDULED)],
)
def test_a_request_waits_the_way_its_admission_chose(triggered, scheduled, expected):
    assert waiting_state(frozenset(triggered), frozenset(scheduled)) is expected
    p = Pending(None, {"op": "tuple"}, ["a", "b"], 0, 0, triggered=frozenset(triggered), scheduled=frozenset(scheduled))
    p.wait()
    assert p.state is expected
    p.wait()  # waiting so already: no move (a move to itself would be refused)
    assert p.state is expected


# ---- the engine moves its requests along the table ----


def test_a_request_answered_at_once_is_answered():
    engine = engine_with(cam=TableCamera().add_periodic(0, 20))
    reply = only(engine.submit(request("image", camera="cam", at=10 * PERIOD), 20 * PERIOD, 1), Reply)
    assert reply.pending.state is ANSWERED and reply.pending.attempts == 1


def test_a_waiting_request_is_answered_when_its_frame_comes():
    cam = TableCamera().add_periodic(0, 20)
    engine = engine_with(cam=cam)
    assert engine.submit(request("image", camera="cam", at=21 * PERIOD), 19 * PERIOD + DELAY, 1) == []
    (pending,) = engine.pending
    assert pending.state is WAITING
    cam.add_periodic(20, 1)
    assert engine.on_frames({"cam"}, 20 * PERIOD + DELAY) == [] and pending.state is WAITING  # still waits
    cam.add_periodic(21, 1)
    assert only(engine.on_frames({"cam"}, 21 * PERIOD + DELAY), Reply).pending.state is ANSWERED


def test_a_request_that_fires_triggers_is_triggered_until_answered():
    trig, free = TableCamera(triggered=True).add(5 * MS), TableCamera().add_periodic(0, 20)
    engine = engine_with(trig=trig, free=free)
    now = 19 * PERIOD + DELAY
    assert engine.submit(request("tuple"), now, 1) == [Trigger(("trig",))]
    (pending,) = engine.pending
    assert pending.state is TRIGGERED
    trig.add(now + 1 * MS, now + 3 * MS)
    assert only(engine.on_frames({"trig"}, now + 3 * MS), Reply).pending.state is ANSWERED


def test_a_scheduled_capture_refused_fails_its_request_once():
    engine = engine_with(trig=TableCamera(triggered=True).add(5 * MS))
    schedule = only(engine.submit(request("image", camera="trig", at=500 * MS, capture=True), 20 * MS, 1), Schedule)
    assert schedule.pending.state is SCHEDULED
    failed = only(engine.fail(schedule.pending, "OUT_OF_RANGE", "too near"), Failure)
    assert failed.pending.state is FAILED and engine.pending == []
    assert engine.fail(schedule.pending, "OUT_OF_RANGE", "again") == [] and schedule.pending.state is FAILED


def test_failing_an_answered_request_is_no_move():
    engine = engine_with(cam=TableCamera().add_periodic(0, 20))
    reply = only(engine.submit(request("latest"), 20 * PERIOD, 1), Reply)
    assert engine.fail(reply.pending, "OUT_OF_RANGE", "late") == [] and reply.pending.state is ANSWERED


def test_a_request_refused_at_admission_fails():
    engine = engine_with(cam=TableCamera().add_periodic(0, 20))
    failure = only(engine.submit(request("image", camera="nope"), 20 * PERIOD, 1), Failure)
    assert failure.code == "UNKNOWN_CAMERA" and failure.pending.state is FAILED and engine.pending == []


def test_a_request_that_times_out_fails():
    engine = engine_with(cam=TableCamera().add_periodic(0, 20))
    assert engine.submit(request("image", camera="cam", at=21 * PERIOD, timeout_ms=100), 20 * PERIOD, 1) == []
    (pending,) = engine.pending
    failure = only(engine.on_tick(pending.deadline), Failure)
    assert failure.code == "TIMEOUT" and pending.state is FAILED and engine.pending == []


def test_a_request_whose_camera_breaks_fails_as_an_internal_error():
    cam = TableCamera().add_periodic(0, 20)
    engine = engine_with(cam=cam)
    assert engine.submit(request("image", camera="cam", at=21 * PERIOD), 20 * PERIOD, 1) == []
    (pending,) = engine.pending
    cam.snapshot = lambda: 1 / 0  # a bug in what the engine reads
    failure = only(engine.on_frames({"cam"}, 20 * PERIOD + MS), Failure)
    assert failure.code == "INTERNAL" and pending.state is FAILED and engine.pending == []


def test_an_overwritten_copy_is_answered_again_then_fails():
    cam = TableCamera().add_periodic(0, 20)
    engine = engine_with(cam=cam)
    reply = only(engine.submit(request("latest"), 20 * PERIOD, 1), Reply)
    for _ in range(COPY_ATTEMPTS - 1):
        reply = only(engine.retry(reply, 21 * PERIOD), Reply)
        assert reply.pending.state is ANSWERED
    failure = only(engine.retry(reply, 22 * PERIOD), Failure)
    assert failure.code == "OVERRUN" and failure.pending.state is FAILED


def test_an_overwritten_copy_waits_again_the_way_it_waited():
    trig, free = TableCamera(triggered=True).add(5 * MS), TableCamera().add_periodic(0, 20)
    engine = engine_with(trig=trig, free=free)
    now = 19 * PERIOD + DELAY
    engine.submit(request("tuple"), now, 1)
    trig.add(now + 1 * MS, now + 3 * MS)
    reply = only(engine.on_frames({"trig"}, now + 3 * MS), Reply)
    trig.frames.clear()  # the triggered frame is gone from the ring: the trigger's frame is awaited again
    assert engine.retry(reply, now + 4 * MS) == []
    assert engine.pending == [reply.pending] and reply.pending.state is TRIGGERED


def test_a_failed_request_handed_back_raises():
    engine = engine_with(cam=TableCamera().add_periodic(0, 20))
    reply = only(engine.submit(request("latest"), 20 * PERIOD, 1), Reply)
    engine.fail(reply.pending, "OUT_OF_RANGE", "x")  # no move: answered
    reply.pending.move(FAILED)  # as if its copy had failed it
    with pytest.raises(IllegalMove, match="a request failed cannot become"):
        engine.retry(reply, 21 * PERIOD)


def test_cancelled_requests_are_cancelled_and_fail_no_more():
    engine = engine_with(cam=TableCamera().add_periodic(0, 20))
    for ticket in (1, 2):
        assert engine.submit(request("image", camera="cam", at=21 * PERIOD), 20 * PERIOD, ticket) == []
    waiting = list(engine.pending)
    engine.cancel_all()
    assert engine.pending == [] and [p.state for p in waiting] == [CANCELLED, CANCELLED]
    assert engine.fail(waiting[0], "OUT_OF_RANGE", "late") == [] and waiting[0].state is CANCELLED
