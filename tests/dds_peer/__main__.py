"""The test peer process: a ROS 2-like (rmw_cyclonedds) node that subscribes, reports what it
gets as JSON lines, and publishes ``std_msgs/msg/Header`` messages when asked.

It shares no code with ``fxis_shm``: its types are its own (``types.py``) and cyclonedds
(de)serializes them, so it is an independent judge of what the package puts on the wire. Its
DDS configuration is the loopback XML, given to ``Domain`` explicitly (``CYCLONEDDS_URI`` is
not read). Start it through ``tests.dds_peer.Peer``; by hand::

    python -m tests.dds_peer --domain 42 --sub /cam0/image_raw:sensor_msgs/msg/Image:sensor_data \\
        --pub-header /frames_at

Profiles: ``sensor_data`` (best effort, keep last 5: rclcpp's SensorDataQoS), ``default``
(reliable, keep last 10) and ``xcdr2`` (``default`` accepting only XCDR2, which no ROS reader
does: for the tests that must see it refused). Every other endpoint says XCDR1, as rmw's do.

stdin takes commands, a JSON object a line: ``{"cmd": "header", "id": 1, "topic": "/frames_at",
"sec": 1, "nanosec": 2, "frame_id": "cam0", "min_readers": 1, "timeout": 10}`` publishes once
the topic's writer matches ``min_readers`` readers, answering ``published`` or ``error`` with
the same id. stdout: ``ready``, ``matched``, ``incompatible_qos``, ``sample``,
``publication_matched``, ``published``, ``error``, ``bye``. The peer ends when stdin closes, on
SIGTERM or after ``--timeout`` seconds.
"""

import argparse
import json
import queue
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any

from cyclonedds.core import DDSStatus, GuardCondition, WaitSet
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from ..peer_fields import describe, peer_parser, run_peer
from .config import loopback_config
from .types import BY_ROS_NAME, Header, Time

HEADER = "std_msgs/msg/Header"
XCDR1 = Policy.DataRepresentation(use_cdrv0_representation=True)
XCDR2 = Policy.DataRepresentation(use_xcdrv2_representation=True)
PROFILES = {"sensor_data": (False, 5, XCDR1), "default": (True, 10, XCDR1), "xcdr2": (True, 10, XCDR2)}
READER_STATUSES = DDSStatus.DataAvailable | DDSStatus.SubscriptionMatched | DDSStatus.RequestedIncompatibleQos


def emit(**event: Any) -> None:
    sys.stdout.write(json.dumps(event, separators=(",", ":")) + "\n")
    sys.stdout.flush()


def qos_of(profile: str) -> Qos:
    if profile not in PROFILES:
        raise SystemExit(f"unknown profile {profile!r}; known: {', '.join(PROFILES)}")
    reliable, depth, representation = PROFILES[profile]
    reliability = (
        Policy.Reliability.Reliable(max_blocking_time=duration(infinite=True))
        if reliable
        else Policy.Reliability.BestEffort
    )
    return Qos(reliability, Policy.History.KeepLast(depth), Policy.Durability.Volatile, representation)


def matched_writers(reader: DataReader) -> list[dict[str, Any]]:
    """What discovery said of each writer matched: names, USER_DATA, representation, reliability."""
    writers = []
    for handle in reader.get_matched_publications():
        endpoint = reader.get_matched_publication_data(handle)
        if endpoint is None:
            continue
        qos = endpoint.qos
        representation = qos[Policy.DataRepresentation] if Policy.DataRepresentation in qos else None
        writers.append(
            {
                "topic_name": endpoint.topic_name,
                "type_name": endpoint.type_name,
                "user_data": qos[Policy.Userdata].data.decode(errors="replace") if Policy.Userdata in qos else None,
                "xcdr1": bool(representation and representation.use_cdrv0_representation),
                "xcdr2": bool(representation and representation.use_xcdrv2_representation),
                "reliable": Policy.Reliability in qos
                and isinstance(qos[Policy.Reliability], Policy.Reliability.Reliable),
                "has_type_id": endpoint.type_id is not None,
            }
        )
    return writers


@dataclass
class Subscription:
    topic: str
    ros_type: str
    profile: str
    reader: DataReader
    matched: int = -1
    incompatible: int = 0

    def label(self) -> dict[str, str]:
        return {"topic": self.topic, "type": self.ros_type, "profile": self.profile}


class PeerNode:
    def __init__(self, args: argparse.Namespace) -> None:
        self.with_data = args.data
        self.domain = Domain(args.domain, loopback_config())
        self.participant = DomainParticipant(args.domain, qos=Qos(Policy.Userdata(b"enclave=/;")))
        self.waitset = WaitSet(self.participant)
        self.wake = GuardCondition(self.participant)  # set by the stdin thread: a command came
        self.waitset.attach(self.wake)
        self.topics: dict[tuple[str, str], Topic] = {}
        self.writers: dict[str, tuple[DataWriter, list[int]]] = {}  # topic -> writer, [matched count]
        self.subscriptions = [self.subscribe(*spec.rsplit(":", 2)) for spec in args.sub]
        for spec in args.pub_header:
            topic, _, profile = spec.partition(":")
            self.header_writer(topic, profile or "default")
        self.commands: queue.Queue[dict[str, Any] | None] = queue.Queue()
        self.pending: list[tuple[float, dict[str, Any]]] = []
        self.stopping = False

    def topic(self, name: str, ros_type: str) -> Topic:
        if (name, ros_type) not in self.topics:
            self.topics[(name, ros_type)] = Topic(self.participant, "rt" + name, BY_ROS_NAME[ros_type])
        return self.topics[(name, ros_type)]

    def subscribe(self, topic: str, ros_type: str, profile: str) -> Subscription:
        reader = DataReader(self.participant, self.topic(topic, ros_type), qos=qos_of(profile))
        reader.set_status_mask(READER_STATUSES)
        self.waitset.attach(reader)
        return Subscription(topic, ros_type, profile, reader)

    def header_writer(self, topic: str, profile: str = "default") -> DataWriter:
        if topic not in self.writers:
            writer = DataWriter(self.participant, self.topic(topic, HEADER), qos=qos_of(profile))
            writer.set_status_mask(DDSStatus.PublicationMatched)
            self.waitset.attach(writer)
            self.writers[topic] = (writer, [0])
        return self.writers[topic][0]

    def read_stdin(self) -> None:
        for line in sys.stdin:
            try:
                self.commands.put(json.loads(line))
            except json.JSONDecodeError:
                self.commands.put({"cmd": None, "line": line})  # answered as unknown, by the main thread
            self.wake.set(True)
        self.commands.put(None)  # stdin closed: the test is done with us
        self.wake.set(True)

    def poll(self, sub: Subscription) -> None:
        matched = sub.reader.get_subscription_matched_status()
        if matched.current_count != sub.matched:
            sub.matched = matched.current_count
            emit(
                event="matched",
                **sub.label(),
                current=matched.current_count,
                total=matched.total_count,
                writers=matched_writers(sub.reader),
            )
        refused = sub.reader.get_requested_incompatible_qos_status()
        if refused.total_count != sub.incompatible:
            sub.incompatible = refused.total_count
            emit(event="incompatible_qos", **sub.label(), total=refused.total_count, policy_id=refused.last_policy_id)
        while samples := sub.reader.take(N=64):
            for sample in samples:
                info = sample.sample_info
                if info.valid_data:
                    fields = describe(sub.ros_type, sample, self.with_data)
                    emit(event="sample", **sub.label(), source_timestamp=info.source_timestamp, **fields)

    def run_commands(self) -> None:
        while True:
            try:
                command = self.commands.get_nowait()
            except queue.Empty:
                return
            if command is None:
                self.stopping = True
            elif command.get("cmd") == "header":
                self.header_writer(command["topic"], command.get("profile", "default"))
                self.pending.append((time.monotonic() + float(command.get("timeout", 10)), command))
            else:
                emit(event="error", id=command.get("id"), message=f"unknown command {command!r}")

    def publish_pending(self) -> None:
        waiting = []
        for deadline, command in self.pending:
            writer = self.writers[command["topic"]][0]
            if writer.get_publication_matched_status().current_count >= command.get("min_readers", 1):
                stamp = Time(sec=command["sec"], nanosec=command["nanosec"])
                writer.write(Header(stamp=stamp, frame_id=command.get("frame_id", "")))
                emit(
                    event="published",
                    id=command.get("id"),
                    topic=command["topic"],
                    stamp=[stamp.sec, stamp.nanosec],
                    frame_id=command.get("frame_id", ""),
                )
            elif time.monotonic() > deadline:
                emit(event="error", id=command.get("id"), message=f"no reader of {command['topic']} matched in time")
            else:
                waiting.append((deadline, command))
        self.pending = waiting

    def report_writers(self) -> None:
        for topic, (writer, last) in self.writers.items():
            current = writer.get_publication_matched_status().current_count
            if current != last[0]:
                last[0] = current
                emit(event="publication_matched", topic=topic, current=current)

    def run(self, lifetime: float) -> None:
        threading.Thread(target=self.read_stdin, daemon=True).start()
        emit(event="ready", guid=str(self.participant.guid))
        end = time.monotonic() + lifetime
        while not self.stopping and time.monotonic() < end:
            # Every status change of interest and every command wakes the wait; the timeout
            # only bounds how late a pending publish's deadline is noticed.
            soonest = min([1.0, *(deadline - time.monotonic() for deadline, _ in self.pending)])
            self.waitset.wait(duration(seconds=max(soonest, 0.0)))
            self.wake.take()
            for sub in self.subscriptions:
                self.poll(sub)
            self.report_writers()
            self.run_commands()
            self.publish_pending()
        emit(event="bye")


def main() -> int:
    args = peer_parser("python -m tests.dds_peer", __doc__.split("\n\n")[0]).parse_args()
    return run_peer(PeerNode(args), args.timeout)


if __name__ == "__main__":
    sys.exit(main())
