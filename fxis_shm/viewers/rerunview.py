"""``fxis view --rerun``: a running service (or a cell of several) seen live in Rerun, through the
public client API only. Every 1/rate s the newest joint tuple of the cameras is asked for; each
camera's frame that is new since the last tuple is logged as an image at its capture time (the
caller's clock) and frame id, and the tuple's skew and sync verdict as scalars
(fxis_shm.formats.rerunlog: the same entities and timelines as ``fxis export --rerun``).

A tuple that does not come (a service down, a refusal) is counted and the next is asked: the
view goes on, and is bounded only by ``seconds``, ``ticks`` or Ctrl-C.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from fxis_shm.client.api import ClientApi
from fxis_shm.client.frames import FrameTuple
from fxis_shm.errors import FxisError
from fxis_shm.formats.rerunlog import RerunLog


@dataclass
class Viewed:
    """What a view logged: frames per camera, tuples, and why ticks got no tuple (message -> count)."""

    cameras: list[str]
    frames: Counter[str] = field(default_factory=Counter)
    tuples: int = 0
    synced: int = 0
    errors: Counter[str] = field(default_factory=Counter)
    interrupted: bool = False

    def describe(self) -> str:
        frames = ", ".join(f"{cam} {self.frames[cam]}" for cam in self.cameras)
        errors = "".join(f"; no tuple ({n}x): {why}" for why, n in self.errors.items())
        return f"{self.tuples} tuples ({self.synced} synced), new frames per camera: {frames}{errors}"


@dataclass
class LiveView:
    client: ClientApi
    cameras: list[str]
    log: RerunLog
    threshold_ms: float
    seen: dict[str, tuple[int, int]] = field(default_factory=dict)  # camera -> (generation, frame id) logged last

    def run(
        self,
        rate_hz: float,
        seconds: float | None = None,
        ticks: int | None = None,
        sleep: Callable[[float], None] = time.sleep,
    ) -> Viewed:
        """Ask a tuple every 1/``rate_hz`` s, for ``seconds`` or ``ticks`` asks (None: until Ctrl-C)."""
        viewed = Viewed(list(self.cameras))
        interval = round(1e9 / rate_hz)
        clock = self.client.clock
        next_t = clock()
        end = None if seconds is None else next_t + round(seconds * 1e9)
        asked = 0
        try:
            while (ticks is None or asked < ticks) and (end is None or clock() < end):
                now = clock()
                if now < next_t:
                    sleep((next_t - now) / 1e9)
                next_t = max(next_t + interval, now)  # behind: the next tick now, never a burst
                asked += 1
                try:
                    tuple_ = self.client.tuple(self.cameras, partial=True)
                except FxisError as exc:
                    viewed.errors[" ".join(str(exc).split())] += 1
                    continue
                with tuple_:
                    self.show(tuple_, viewed)
        except KeyboardInterrupt:
            viewed.interrupted = True
        return viewed

    def show(self, tuple_: FrameTuple, viewed: Viewed) -> None:
        for name, frame in tuple_.items():
            identity = (frame.generation, frame.frame_id)
            if self.seen.get(name) != identity:  # a frame shown already (rate above the camera's) is not logged again
                self.log.image(name, frame.image, frame.t_capture, frame.frame_id)
                self.seen[name] = identity
                viewed.frames[name] += 1
        captures = [frame.t_capture for frame in tuple_.values()]
        complete = set(self.cameras) <= set(tuple_)
        t_tuple = tuple_.t_request if tuple_.t_request is not None else max(captures, default=self.client.clock())
        synced = self.log.sync(t_tuple, captures, complete, self.threshold_ms)
        viewed.tuples += 1
        viewed.synced += synced
