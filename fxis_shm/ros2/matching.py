"""Who the bridge's topics reach: per topic, the endpoints matched now and those discovered that
could not match, and why (an incompatible QoS policy, an incompatible type), for ``fxis status``
(key ``ros2``, ``topics``) and the bridge's log. Without it, a node that cannot match sees nothing
and neither side says so.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

log = logging.getLogger("ros2")


class TopicMatches:
    """One topic's matches. ``counter`` reads the endpoints matched now; ``poll`` (if any) reads
    the refusals a DDS implementation keeps as a status rather than reporting as events."""

    def __init__(self, topic: str) -> None:
        self.topic = topic
        self.counter: Callable[[], int] = lambda: 0
        self.poll: Callable[[TopicMatches], None] | None = None
        self.qos_refusals: dict[str, int] = {}  # QoS policy -> endpoints refused for it so far
        self.type_refusals = 0
        self._logged = 0

    def incompatible_qos(self, policy: str, total: int) -> None:
        self.qos_refusals[policy] = max(total, self.qos_refusals.get(policy, 0) + 1)

    def incompatible_type(self, total: int) -> None:
        self.type_refusals = max(total, self.type_refusals + 1)

    @property
    def refused(self) -> int:
        return sum(self.qos_refusals.values()) + self.type_refusals

    def why(self) -> list[str]:
        reasons = [f"{count} with an incompatible {policy} QoS" for policy, count in sorted(self.qos_refusals.items())]
        if self.type_refusals:
            reasons.append(f"{self.type_refusals} with an incompatible type")
        return reasons

    def as_dict(self) -> dict[str, Any]:
        if self.poll is not None:
            self.poll(self)
        if self.refused > self._logged:  # each new refusal is logged once
            log.warning("%s: %s could not match: %s", self.topic, self.refused - self._logged, "; ".join(self.why()))
            self._logged = self.refused
        return {"matched": self.counter(), "refused": self.refused, "why": self.why()}


class MatchTable:
    """Every topic's :class:`TopicMatches` of one participant, made on first use."""

    def __init__(self) -> None:
        self._topics: dict[str, TopicMatches] = {}

    def of(self, topic: str) -> TopicMatches:
        if topic not in self._topics:
            self._topics[topic] = TopicMatches(topic)
        return self._topics[topic]

    def status(self) -> dict[str, dict[str, Any]]:
        """Per topic: endpoints matched now, how many could not match and why."""
        return {topic: matches.as_dict() for topic, matches in sorted(self._topics.items())}
