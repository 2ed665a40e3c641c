"""What the bridge's topic modules ask of a participant, whichever way it joins the graph
(fxis_shm.ros2.participants: a Cyclone participant or an rclpy node): the QoS profiles of its
endpoints and the requests it reads. Imports no DDS library.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

from fxis_shm.formats import cdr
from fxis_shm.ros2.matching import MatchTable


@dataclass(frozen=True)
class QosProfile:
    """The part of an rmw QoS profile that decides matching, and a writer's blocking bound."""

    reliable: bool = True
    depth: int = 10
    transient_local: bool = False
    # RELIABILITY.max_blocking_time (not part of matching); None: infinite, as rmw has it.
    max_blocking_ms: float | None = None


# rclcpp's SensorDataQoS: best effort, keep last 5, volatile.
SENSOR_DATA = QosProfile(reliable=False, depth=5)
# rclcpp's default, QoS(10): reliable, keep last 10, volatile.
DEFAULT_SUBSCRIBER = QosProfile(reliable=True, depth=10)
# A camera's publisher: reliable, so that both kinds of subscriber above match. Keep last 10, as
# QoS(10): a reliable reader whose datagrams were dropped (a full receive buffer) gets them resent
# only while they are still in the writer's history; with 2, a repair slower than 2 frame periods
# left gaps in a Fast DDS node's ids.
CAMERA_PUBLISHER = QosProfile(reliable=True, depth=10, max_blocking_ms=100)


@dataclass(frozen=True)
class ReceivedHeader:
    """A request: the Header, and the DDS source timestamp its publisher gave it (ns)."""

    header: cdr.Header
    source_timestamp_ns: int


HEADER, STRING = "std_msgs/msg/Header", "std_msgs/msg/String"  # the types requests come as


def decode_requests(ros_type: str, received: list[tuple[bytes, int]]) -> list[Any]:
    """Requests as they arrived, (CDR, source timestamp ns), decoded: a Header as a
    :class:`ReceivedHeader`, a String as its text. A malformed one is dropped."""
    requests: list[Any] = []
    for data, source_timestamp in received:
        try:
            if ros_type == HEADER:
                requests.append(ReceivedHeader(cdr.decode_header(data), source_timestamp))
            else:
                requests.append(cdr.decode_string(data))
        except cdr.CdrError:
            continue
    return requests


class Writer(Protocol):
    """Publishes pre-built CDR messages (encapsulation header included) of one topic and type."""

    ros_topic: str

    def write(self, payload: bytes | bytearray | memoryview, timestamp_ns: int | None = None) -> None: ...

    def matched_count(self) -> int: ...


class RequestReader(Protocol):
    """Reads requests of one topic (:func:`decode_requests`)."""

    def wait(self, timeout: float) -> list[Any]: ...

    def matched_count(self) -> int: ...


class Participant(Protocol):
    """A way onto the ROS 2 graph: ``dds.RosParticipant`` or ``rclpynode.RclpyNode``."""

    VIA: str
    matches: MatchTable

    def writer(self, ros_topic: str, ros_type: str, profile: QosProfile | None = None) -> Writer: ...

    def header_reader(self, ros_topic: str, profile: QosProfile | None = None) -> RequestReader: ...

    def string_reader(self, ros_topic: str, profile: QosProfile | None = None) -> RequestReader: ...

    def close(self) -> None: ...
