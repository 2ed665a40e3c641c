"""The life of a request in the engine: its named states and the moves allowed between them.

::

    RECEIVED --admitted--> WAITING | TRIGGERED | SCHEDULED --planned--> ANSWERED
        |                        |          |                             |
        +--refused--> FAILED <---+          +--cancel_all--> CANCELLED    +--retry: planned again,
                        ^                                                 |  waits again (as before)
                        +-------------------------------------------------+  or fails

A request is RECEIVED while it is admitted. Admitted, it waits in one of three ways, fixed at
admission: for frames (WAITING), for the frames of the software triggers it fired now
(TRIGGERED), or for the capture it had scheduled at t* (SCHEDULED). A plan moves it to ANSWERED:
the caller copies the frames out and replies. Should that copy find a slot overwritten, the
caller hands it back (``engine.retry``): it is planned again, waits again the way it waited
before, or fails.

What a failure does: every failure (refused at admission, a timeout, a camera down, no frame
coming, a capture that could not be scheduled, overwritten frames after the last copy attempt,
an internal error) moves the request to FAILED, and the caller gets one ``Failure`` for it: its
one error reply. FAILED and CANCELLED are final: the request has left the engine, nothing moves
it again, and its fields stay as they were (for the error reply and the log). A failure of a
request already ANSWERED, FAILED or CANCELLED is no move (``engine.fail`` returns nothing: its
answer went out first). Triggers fired and captures scheduled for it are not taken back: their
frames are stored as any others.

A move outside ``MOVES`` is a bug in the engine and raises ``IllegalMove``.
"""

from __future__ import annotations

from enum import Enum


class RequestState(Enum):
    RECEIVED = "received"  # being admitted
    WAITING = "waiting"  # admitted, waits for frames
    TRIGGERED = "triggered"  # admitted, waits for the frames of the software triggers it fired
    SCHEDULED = "scheduled"  # admitted, waits for the capture it scheduled at t* (capture=True)
    ANSWERED = "answered"  # planned: the caller copies the frames out and replies (or hands it back)
    FAILED = "failed"  # its one error reply went out: final
    CANCELLED = "cancelled"  # its caller gave up on it: final


RECEIVED, WAITING, TRIGGERED, SCHEDULED, ANSWERED, FAILED, CANCELLED = RequestState
WAITING_STATES = frozenset({WAITING, TRIGGERED, SCHEDULED})  # in the engine's list of waiting requests

# The one table of allowed moves: state -> the states it may become.
MOVES: dict[RequestState, frozenset[RequestState]] = {
    RECEIVED: WAITING_STATES | {FAILED},
    WAITING: frozenset({ANSWERED, FAILED, CANCELLED}),
    TRIGGERED: frozenset({ANSWERED, FAILED, CANCELLED}),
    SCHEDULED: frozenset({ANSWERED, FAILED, CANCELLED}),
    ANSWERED: WAITING_STATES | {ANSWERED, FAILED},
    FAILED: frozenset(),
    CANCELLED: frozenset(),
}


class IllegalMove(Exception):
    """A move ``MOVES`` does not allow: a bug in whoever moved the request."""

    def __init__(self, state: RequestState, to: RequestState):
        super().__init__(f"a request {state.value} cannot become {to.value}")
        self.state = state
        self.to = to


def checked_move(state: RequestState, to: RequestState) -> RequestState:
    """``to``, if a request ``state`` may become it; else raises IllegalMove."""
    if to not in MOVES[state]:
        raise IllegalMove(state, to)
    return to


def waiting_state(triggered: frozenset[str], scheduled: frozenset[str]) -> RequestState:
    """How an admitted request waits, from what its admission did: scheduled a capture at t*,
    fired software triggers, or neither."""
    if scheduled:
        return SCHEDULED
    if triggered:
        return TRIGGERED
    return WAITING
