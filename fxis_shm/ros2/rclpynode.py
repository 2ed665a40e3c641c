"""The bridge as a real ROS 2 node: publishes through rclpy on whatever RMW the host's ROS 2 runs
(``RMW_IMPLEMENTATION``; Fast DDS by default), where rclpy can be imported.

It offers what :class:`fxis_shm.ros2.dds.RosParticipant` offers the bridge (``writer``,
``header_reader``, ``topic_status``, ``close``), so every topic module works on either. What
changes is the transport: a Fast DDS node on the same host gets each frame through Fast DDS's
shared memory, as from any other rclpy publisher, instead of UDP datagrams that overrun its
default 208 KiB receive buffer; and the bridge is a node like any other (``ros2 node list``,
``rqt_graph``, its graph events), with nothing to set on either side.

Messages go out already serialized (``Publisher.publish(bytes)``, rmw's
``publish_serialized_message``): the pixels are copied once into the CDR, as on the Cyclone
path, and rmw copies that buffer once into its transport; no Python message is built.
"""

from __future__ import annotations

import importlib
import logging
import threading
import time
from collections import deque
from typing import Any

from fxis_shm.ros2.endpoints import CAMERA_PUBLISHER, DEFAULT_SUBSCRIBER, HEADER, STRING, QosProfile, decode_requests
from fxis_shm.ros2.matching import MatchTable
from fxis_shm.ros2.vendors import use_fastdds_transports

log = logging.getLogger("ros2")

SPIN_PERIOD_S = 0.05  # the executor's wait: how soon a stop is seen


def rclpy_available() -> str | None:
    """None if rclpy can be imported here, else why not (the import's error)."""
    try:
        importlib.import_module("rclpy")
    except Exception as exc:  # an ImportError, or a ROS install whose libraries are not found
        return f"{type(exc).__name__}: {exc}"
    return None


def message_class(ros_type: str) -> type:
    """``sensor_msgs/msg/Image`` -> the rclpy message class (from the ROS install's packages)."""
    package, kind, name = ros_type.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


class RclpyNode:
    """One rclpy context and node (name ``node_name`` in ``namespace``), spun by a thread of its
    own for the requests it reads and the graph events it counts; a context manager."""

    VIA = "rclpy"

    def __init__(self, domain_id: int, node_name: str, namespace: str = "") -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self.domain_id = domain_id
        use_fastdds_transports()
        self._context = Context()
        # the bridge's process handles its own signals (fxis_shm.service.stopsignals)
        rclpy.init(context=self._context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(node_name, namespace=namespace or "/", context=self._context)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self.node)
        self.matches = MatchTable()  # per topic: who matched, who could not and why
        self._closed = threading.Event()
        self._spinner = threading.Thread(target=self._spin, name="rclpy", daemon=True)
        self._spinner.start()

    def _spin(self) -> None:
        while not self._closed.is_set():
            try:
                self._executor.spin_once(timeout_sec=SPIN_PERIOD_S)
            except Exception:  # the context went away under us at close
                if not self._closed.is_set():
                    log.exception("rclpy executor")
                return

    def writer(self, ros_topic: str, ros_type: str, profile: QosProfile | None = None) -> RclpyWriter:
        return RclpyWriter(self, ros_topic, ros_type, profile or CAMERA_PUBLISHER)

    def header_reader(self, ros_topic: str, profile: QosProfile | None = None) -> RclpyRequestReader:
        return RclpyRequestReader(self, ros_topic, HEADER, profile or DEFAULT_SUBSCRIBER)

    def string_reader(self, ros_topic: str, profile: QosProfile | None = None) -> RclpyRequestReader:
        return RclpyRequestReader(self, ros_topic, STRING, profile or DEFAULT_SUBSCRIBER)

    def close(self) -> None:
        """Stop spinning, destroy the node and shut the context down; idempotent."""
        if self._closed.is_set():
            return
        self._closed.set()
        self._spinner.join(timeout=2)
        try:
            self._executor.shutdown(timeout_sec=1)
            self.node.destroy_node()
        finally:
            if self._context.ok():
                self._context.try_shutdown()

    def __enter__(self) -> RclpyNode:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def qos_of(profile: QosProfile) -> Any:
    """The rclpy QoS of a profile (rclpy has no max_blocking_time: rmw chooses)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=profile.depth,
        reliability=ReliabilityPolicy.RELIABLE if profile.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if profile.transient_local else DurabilityPolicy.VOLATILE,
    )


class RclpyWriter:
    """Publishes pre-built CDR messages (encapsulation header included) of one topic and type."""

    def __init__(self, node: RclpyNode, ros_topic: str, ros_type: str, profile: QosProfile) -> None:
        from rclpy.event_handler import PublisherEventCallbacks

        self.ros_topic, self.ros_type = ros_topic, ros_type
        matches = node.matches.of(ros_topic)
        callbacks = PublisherEventCallbacks(
            incompatible_qos=lambda info: matches.incompatible_qos(info.last_policy_kind.name, info.total_count),
            incompatible_type=lambda info: matches.incompatible_type(info.total_count),
        )
        self._publisher = node.node.create_publisher(
            message_class(ros_type), ros_topic, qos_of(profile), event_callbacks=callbacks
        )
        matches.counter = self.matched_count

    def write(self, payload: bytes | bytearray | memoryview, timestamp_ns: int | None = None) -> None:
        """Publish one serialized message. ``timestamp_ns`` is not settable through rclpy: rmw
        stamps the source time itself."""
        self._publisher.publish(payload if isinstance(payload, bytes) else bytes(payload))

    def matched_count(self) -> int:
        return int(self._publisher.get_subscription_count())

    def wait_for_readers(self, n: int = 1, timeout: float = 5.0) -> bool:
        deadline = time.monotonic() + timeout
        while self.matched_count() < n:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.005)  # rclpy offers no wait on a match; 5 ms is far below discovery's pace
        return True

    def wait_for_acks(self, timeout: float = 5.0) -> bool:
        from rclpy.duration import Duration

        return bool(self._publisher.wait_for_all_acked(Duration(nanoseconds=int(timeout * 1e9))))


class RclpyRequestReader:
    """Reads requests (Header or String) as CDR (``raw=True``), decoded as on the Cyclone path
    (:func:`fxis_shm.ros2.endpoints.decode_requests`); the executor's thread queues them,
    ``wait`` hands them over."""

    QUEUE_LIMIT = 256  # requests beyond this, unread, are dropped oldest first

    def __init__(self, node: RclpyNode, ros_topic: str, ros_type: str, profile: QosProfile) -> None:
        self.ros_topic, self.ros_type = ros_topic, ros_type
        self._queue: deque[bytes] = deque(maxlen=self.QUEUE_LIMIT)
        self._arrived = threading.Condition()
        self._subscription = node.node.create_subscription(
            message_class(ros_type), ros_topic, self._on_message, qos_of(profile), raw=True
        )
        node.matches.of(ros_topic).counter = self.matched_count

    def _on_message(self, data: bytes) -> None:
        with self._arrived:
            self._queue.append(data)
            self._arrived.notify_all()

    def take(self) -> list[Any]:
        with self._arrived:
            received, self._queue = list(self._queue), deque(maxlen=self.QUEUE_LIMIT)
        return decode_requests(self.ros_type, [(data, 0) for data in received])  # rclpy gives no source time here

    def wait(self, timeout: float) -> list[Any]:
        with self._arrived:
            if not self._queue:
                self._arrived.wait(timeout)
        return self.take()

    def matched_count(self) -> int:
        return int(self._subscription.get_publisher_count())
