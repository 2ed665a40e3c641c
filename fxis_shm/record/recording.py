"""What a recording takes next from the rings, and what it missed (``fxis record``).

A recorder polls each camera's frame list (the ``frames`` op: ids and times, no pixels)
and takes the frames it has not taken yet, as one sequence. Two kinds of gap in the
frame ids are told apart, because only one of them is the recorder's fault:

- the camera skipped ids (it dropped frames before the ring saw them): the gap lies
  between two frames the ring holds, so the recorder could not have had them;
- the ring came round before the recorder took them (it fell behind): the last frame
  taken is no longer in the ring, and every id between it and the oldest held is missed.

A camera whose worker restarted starts a new generation of its ring, counting its ids afresh:
what the restart cost is the time between the last frame seen of one generation and the first
of the next, over the camera's period (a RestartGap; docs/recording.md).

Pure: frame rows and times in, decisions out.
"""

from __future__ import annotations

import copy
import json
from dataclasses import asdict, dataclass, field

from fxis_shm.core.decimation import Decimator

# The columns of a ``frames`` row (fxis_shm.shm.cameras.FRAME_FIELDS).
ID, T_CAPTURE, GENERATION = 0, 1, 4


@dataclass(frozen=True)
class RestartGap:
    """The frames a camera's restart cost a recording: none between ``last`` (id, capture time),
    the last frame of ``generations[0]``, and ``first``, the first of ``generations[1]``."""

    generations: tuple[int, int]
    last: tuple[int, int]
    first: tuple[int, int]
    missing: int | None  # frames the camera would have captured between, None: it has no period

    @classmethod
    def between(cls, generation: int, last_id: int, last_t: int, first: list[int], period_ns: int) -> RestartGap:
        gap_ns = first[T_CAPTURE] - last_t
        missing = max(0, round(gap_ns / period_ns) - 1) if period_ns else None
        return cls((generation, first[GENERATION]), (last_id, last_t), (first[ID], first[T_CAPTURE]), missing)

    @property
    def gap_ms(self) -> float:
        return (self.first[1] - self.last[1]) / 1e6

    def describe(self) -> str:
        count = "an unknown number of frames (no period)" if self.missing is None else f"{self.missing} frames"
        return (
            f"generation {self.generations[0]} -> {self.generations[1]}: {count} missing in {self.gap_ms:.0f} ms "
            f"(after frame {self.last[0]}, before frame {self.first[0]} of the next)"
        )


@dataclass
class Follower:
    """One camera's recording: the frames taken so far and those missed."""

    t_start: int  # frames captured before this are not part of the recording
    rate_hz: float | None = None  # None: every frame; else thinned on purpose to this rate
    last_id: int | None = None
    last_t: int | None = None
    generation: int | None = None
    missed: int = 0  # frames the ring held but the recorder did not take in time
    taken: int = 0
    restarts: list[RestartGap] = field(default_factory=list)  # what each restart of its worker cost
    decimator: Decimator = field(init=False)
    # what the last new_frames changed, for give_back: last_id, last_t, generation, restarts, missed
    _before: tuple = field(init=False, repr=False)
    _decimator_before: Decimator = field(init=False, repr=False)

    def __post_init__(self):
        self.decimator = Decimator(self.rate_hz)
        self._before, self._decimator_before = (None, None, None, 0, 0), copy.copy(self.decimator)

    def new_frames(self, rows: list[list[int]], period_ns: int) -> list[list[int]]:
        """The rows (oldest first, as the ``frames`` op lists them) to take now. Counts
        what fell out of the ring since the last call into ``missed``, and what each restart
        cost: a restarted worker keeps its ring, so one listing may hold the last frames of
        one generation and the first of the next, and every change of generation between two
        rows is a restart (not only one at the first row)."""
        self._before = (self.last_id, self.last_t, self.generation, len(self.restarts), self.missed)
        self._decimator_before = copy.copy(self.decimator)
        fresh = [
            r for r in rows if r[T_CAPTURE] >= self.t_start and (self.last_t is None or r[T_CAPTURE] > self.last_t)
        ]
        if not fresh:
            return []
        same_generation = fresh[0][GENERATION] == self.generation
        if (
            same_generation
            and self.last_id is not None
            and self.last_t is not None
            and rows[0][T_CAPTURE] > self.last_t
        ):
            # the last frame taken has left the ring: everything up to the oldest held is lost
            self.missed += max(0, fresh[0][ID] - self.last_id - 1)
        for row in fresh:
            if row[GENERATION] != self.generation and self.generation is not None:
                # a restarted camera counts its ids afresh: across it, only the capture times tell the gap
                assert self.last_id is not None and self.last_t is not None
                self.restarts.append(RestartGap.between(self.generation, self.last_id, self.last_t, row, period_ns))
            self.last_id, self.last_t, self.generation = row[ID], row[T_CAPTURE], row[GENERATION]
        return [r for r in fresh if self.decimator.offer(r[T_CAPTURE], period_ns)]

    def give_back(self) -> None:
        """The frames the last ``new_frames`` chose could not be copied because the camera went
        down meanwhile: they stay in its ring (its worker, restarted, keeps the ring), so the
        next call offers them again, and a restart's gap is counted from the last frame taken,
        the one the bag holds. Frames the ring no longer holds by then are counted as usual."""
        self.last_id, self.last_t, self.generation, restarts, self.missed = self._before
        del self.restarts[restarts:]
        self.decimator = self._decimator_before

    @property
    def missing_at_restarts(self) -> int:
        return sum(gap.missing or 0 for gap in self.restarts)

    @property
    def lost_to_restarts(self) -> bool:
        """Whether a restart cost frames (or may have: a camera without a period cannot say)."""
        return any(gap.missing != 0 for gap in self.restarts)

    def lost(self, count: int) -> None:
        """Frames chosen but overwritten before their pixels could be copied."""
        self.missed += count


@dataclass
class Steps:
    """``--tuples``: one synchronized tuple at t0 + k/rate for k = 0, 1, ..."""

    t0: int
    rate_hz: float
    next_k: int = 0
    taken: int = 0
    missed: int = 0  # steps whose frames had left the rings before the recorder asked

    @property
    def interval_ns(self) -> float:
        return 1e9 / self.rate_hz

    def time(self, k: int) -> int:
        return self.t0 + round(k * self.interval_ns)  # from t0: no rounding drift

    def due(self, now: int, oldest_held: int, limit: int) -> list[int]:
        """The step times to ask for now (at most ``limit``): those not in the future.
        Steps older than ``oldest_held`` (the newest of the cameras' oldest frames)
        cannot be answered any more and are counted as missed."""
        while self.time(self.next_k) < oldest_held and self.time(self.next_k) <= now:
            self.next_k += 1
            self.missed += 1
        times = []
        while len(times) < limit and self.time(self.next_k + len(times)) <= now:
            times.append(self.time(self.next_k + len(times)))
        return times

    def advance(self, count: int, answered: bool = True) -> None:
        self.next_k += count
        if answered:
            self.taken += count
        else:
            self.missed += count


def restart_record(followers: dict[str, Follower]) -> tuple[str, str]:
    """What the camera restarts cost a recording, for its bag's ``fxis`` record: the ``ended``
    words to add ("" if none restarted) and the gaps as JSON, per camera."""
    restarted = {cam: f for cam, f in followers.items() if f.lost_to_restarts}
    gaps = json.dumps({cam: [asdict(gap) for gap in f.restarts] for cam, f in restarted.items()})
    if not restarted:
        return "", gaps
    each = ", ".join(
        f"{cam} {f.missing_at_restarts} frames in {len(f.restarts)} restart(s)" for cam, f in restarted.items()
    )
    return f"frames missing where cameras restarted: {each}", gaps
