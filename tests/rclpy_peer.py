"""A real ROS 2 node for tests: rclpy on the RMW its environment names (Fast DDS, ROS 2's default,
in its default configuration), from ROS 2's own wheels in a virtualenv of their own (the Makefile
makes them: .venv-ros for Kilted, .venv-ros-jazzy for Jazzy).

It speaks the line protocol of tests/dds_peer (its ``__main__`` documents the commands and the
events), so :class:`tests.dds_peer.Peer` drives either peer; rclpy deserializes every message,
so it judges the bridge's bytes with ROS 2's own type support. It imports nothing from fxis_shm
(the Jazzy venv has none), only tests/peer_fields.py beside it (the fields both peers report).
Run as a script by ``Peer(kind="kilted")``::

    .venv-ros/bin/python tests/rclpy_peer.py --domain 42 --sub /cam0/image_raw:sensor_msgs/msg/Image:default

Extra commands: ``{"cmd": "nodes", "id": 1}`` answers ``nodes`` with the graph's (name, namespace)
pairs; ``{"cmd": "string", "id": 2, "topic": T, "data": TEXT}`` publishes a std_msgs/String as
``header`` does a Header. Extra sample fields: ``diagnostic_msgs/msg/DiagnosticArray`` gives ``status``, a list of
{level, name, message, hardware_id, values}.
"""

import argparse
import importlib
import json
import queue
import sys
import threading
import time
from typing import Any

import rclpy
from peer_fields import describe, peer_parser, run_peer  # tests/, this script's folder
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

HEADER, STRING = "std_msgs/msg/Header", "std_msgs/msg/String"
PROFILES = {
    "sensor_data": (ReliabilityPolicy.BEST_EFFORT, 5),  # rclcpp's SensorDataQoS
    "default": (ReliabilityPolicy.RELIABLE, 10),  # rclcpp's QoS(10)
}
_print_lock = threading.Lock()


def emit(**event: Any) -> None:
    with _print_lock:
        sys.stdout.write(json.dumps(event, separators=(",", ":")) + "\n")
        sys.stdout.flush()


def message_class(ros_type: str) -> Any:
    package, kind, name = ros_type.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def qos_of(profile: str) -> QoSProfile:
    if profile not in PROFILES:
        raise SystemExit(f"unknown profile {profile!r}; known: {', '.join(PROFILES)}")
    reliability, depth = PROFILES[profile]
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=reliability, durability=DurabilityPolicy.VOLATILE
    )


class PeerNode:
    def __init__(self, args: argparse.Namespace) -> None:
        self.with_data = args.data
        rclpy.init(domain_id=args.domain, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(args.name)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.subscriptions = [self.subscribe(*spec.rsplit(":", 2)) for spec in args.sub]
        self.writers: dict[str, Any] = {}
        for spec in args.pub_header:
            topic, _, profile = spec.partition(":")
            self.header_writer(topic, profile or "default")
        for topic in args.pub_string:
            self.header_writer(topic, "default", STRING)
        self.commands: queue.Queue[dict[str, Any] | None] = queue.Queue()
        self.pending: list[tuple[float, dict[str, Any]]] = []
        self.stopping = False

    def subscribe(self, topic: str, ros_type: str, profile: str) -> Any:
        label = {"topic": topic, "type": ros_type, "profile": profile}

        def on_message(message: Any, info: Any) -> None:
            fields = describe(ros_type, message, self.with_data)
            emit(event="sample", **label, source_timestamp=int(info["source_timestamp"]), **fields)

        def on_matched(status: Any) -> None:
            writers = [
                {"node_name": w.node_name, "type_name": w.topic_type, "type_hash": str(w.topic_type_hash)}
                for w in self.node.get_publishers_info_by_topic(topic)
            ]
            emit(event="matched", **label, current=status.current_count, total=status.total_count, writers=writers)

        def on_incompatible(status: Any) -> None:
            emit(event="incompatible_qos", **label, total=status.total_count, policy=status.last_policy_kind.name)

        events = SubscriptionEventCallbacks(matched=on_matched, incompatible_qos=on_incompatible)
        return self.node.create_subscription(
            message_class(ros_type), topic, on_message, qos_of(profile), event_callbacks=events
        )

    def header_writer(self, topic: str, profile: str = "default", ros_type: str = HEADER) -> Any:
        if topic not in self.writers:

            def on_matched(status: Any) -> None:
                emit(event="publication_matched", topic=topic, current=status.current_count)

            events = PublisherEventCallbacks(matched=on_matched)
            self.writers[topic] = self.node.create_publisher(
                message_class(ros_type), topic, qos_of(profile), event_callbacks=events
            )
        return self.writers[topic]

    def read_stdin(self) -> None:
        for line in sys.stdin:
            try:
                self.commands.put(json.loads(line))
            except json.JSONDecodeError:
                self.commands.put({"cmd": None, "line": line})
        self.commands.put(None)

    def run_commands(self) -> None:
        while True:
            try:
                command = self.commands.get_nowait()
            except queue.Empty:
                return
            if command is None:
                self.stopping = True
            elif command.get("cmd") in ("header", "string"):
                ros_type = HEADER if command["cmd"] == "header" else STRING
                self.header_writer(command["topic"], command.get("profile", "default"), ros_type)
                self.pending.append((time.monotonic() + float(command.get("timeout", 10)), command))
            elif command.get("cmd") == "nodes":
                names = self.node.get_node_names_and_namespaces()
                emit(event="nodes", id=command.get("id"), nodes=[[name, ns] for name, ns in names])
            else:
                emit(event="error", id=command.get("id"), message=f"unknown command {command!r}")

    def publish_pending(self) -> None:
        waiting = []
        for deadline, command in self.pending:
            writer = self.writers[command["topic"]]
            if writer.get_subscription_count() >= command.get("min_readers", 1):
                if command["cmd"] == "string":
                    writer.publish(message_class(STRING)(data=command["data"]))
                    emit(event="published", id=command.get("id"), topic=command["topic"], data=command["data"])
                    continue
                header = message_class(HEADER)()
                header.stamp.sec, header.stamp.nanosec = command["sec"], command["nanosec"]
                header.frame_id = command.get("frame_id", "")
                writer.publish(header)
                emit(
                    event="published",
                    id=command.get("id"),
                    topic=command["topic"],
                    stamp=[command["sec"], command["nanosec"]],
                    frame_id=header.frame_id,
                )
            elif time.monotonic() > deadline:
                emit(event="error", id=command.get("id"), message=f"no reader of {command['topic']} matched in time")
            else:
                waiting.append((deadline, command))
        self.pending = waiting

    def run(self, lifetime: float) -> None:
        threading.Thread(target=self.read_stdin, daemon=True).start()
        emit(event="ready", node=self.node.get_name(), rmw=rclpy.get_rmw_implementation_identifier())
        end = time.monotonic() + lifetime
        while not self.stopping and time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)
            self.run_commands()
            self.publish_pending()
        emit(event="bye")
        self.node.destroy_node()
        rclpy.try_shutdown()


def main() -> int:
    parser = peer_parser("rclpy_peer.py", __doc__.split("\n\n")[0])
    parser.add_argument("--name", default="fxis_test_peer", help="the node's name")
    parser.add_argument("--pub-string", action="append", default=[], metavar="TOPIC")
    args = parser.parse_args()
    return run_peer(PeerNode(args), args.timeout)


if __name__ == "__main__":
    sys.exit(main())
