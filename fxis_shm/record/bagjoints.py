"""A robot's joints in a bag (``sensor_msgs/msg/JointState``), sampled at the slots of a
LeRobot export: ``observation.state`` (and ``action``, from a topic the user names) are the
joint positions of the message nearest each slot, within half a slot period; a slot without
one is dropped, as a slot without a camera tuple is.

A message's time is its ``header.stamp`` (its log time if the stamp is 0), moved from the wall
clock to the bag's clock by the ``clock_to_realtime_ns`` that ``fxis record`` states in the bag:
the MCAP log times of a bag are wall-clock times, its capture times the service's clock.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fxis_shm.errors import ConfigError
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.bagfile import RECORD, BagReader


@dataclass
class JointTrack:
    topic: str
    names: list[str]
    times: list[int]  # in the bag's clock, in time order
    positions: np.ndarray  # (messages, joints)

    def nearest(self, t: int, within_ns: float) -> int | None:
        """The message nearest ``t`` if it lies within ``within_ns`` of it, else None."""
        i = bisect.bisect_left(self.times, t)
        near = [j for j in (i - 1, i) if 0 <= j < len(self.times)]
        best = min(near, key=lambda j: abs(self.times[j] - t))
        return best if abs(self.times[best] - t) <= within_ns else None


def joint_topics(bag: BagReader) -> list[str]:
    return sorted(t for t, kind in bag.topics.items() if kind == rosmsgs.JOINT_STATE)


def choose_topics(bag: BagReader, state: str | None, action: str | None) -> tuple[str | None, str | None]:
    """The state and action topics: those named (each must be a JointState topic of the bag),
    else the bag's one JointState topic as the state; ConfigError when that is ambiguous."""
    have = joint_topics(bag)
    for flag, topic in (("--state-topic", state), ("--action-topic", action)):
        if topic is not None and topic not in have:
            said = f"its JointState topics: {', '.join(have)}" if have else "it holds no sensor_msgs/msg/JointState"
            raise ConfigError(f"{flag} {topic}: not a JointState topic of {bag.path}; {said}")
    if state is None and action is None and len(have) > 1:
        raise ConfigError(f"{bag.path} holds several JointState topics ({', '.join(have)}): name --state-topic")
    if state is None and action is None and have:
        state = have[0]
    return state, action


def joint_track(bag: BagReader, topic: str) -> JointTrack:
    to_realtime = int(bag.metadata.get(RECORD, {}).get("clock_to_realtime_ns", 0) or 0)
    names: list[str] = []
    times: list[int] = []
    positions: list[Sequence[float]] = []
    for log_time, m in bag.messages(topic):
        names = names or list(m.name)
        if list(m.name) != names or len(m.position) != len(names):
            raise ConfigError(f"{topic}: its messages name different joints ({names} then {list(m.name)})")
        stamp = rosmsgs.stamp_ns(m.header.stamp) or log_time
        times.append(stamp - to_realtime)
        positions.append(list(m.position))
    if not times:
        raise ConfigError(f"{topic}: no messages")
    order = np.argsort(times, kind="stable")
    return JointTrack(topic, names, [times[i] for i in order], np.asarray(positions, np.float32)[order])
