"""A ROS 2 participant on plain Cyclone DDS (the ``cyclonedds`` wheel, no ROS install): writers
of pre-built CDR messages and a reader of ``std_msgs/msg/Header`` requests.

What makes a ROS 2 node (rmw_cyclonedds_cpp) talk to us:

* names: topic ``/a/b`` is DDS topic ``rt/a/b``, type ``pkg/msg/Name`` is
  ``pkg::msg::dds_::Name_`` (``fxis_shm.formats.rosnames``);
* payload: XCDR1 (classic CDR), little endian, key-less, ``final`` (``fxis_shm.formats.cdr``);
* QoS: DATA_REPRESENTATION = [XCDR1] on every endpoint, since rmw_cyclonedds' sertype allows
  only XCDR1 and Cyclone never matches an XCDR2 writer with its readers; reliability, history
  and durability as the ROS profiles below, the rest as rmw's ``create_readwrite_qos``;
* USER_DATA: ``enclave=/;`` on the participant and ``typehash=RIHS01_<hex>;`` on endpoints, as
  rmw_cyclonedds ≥ Iron writes them (informational: rmw never refuses a match on them).

rmw_cyclonedds' sertype carries no XTypes type information, so Cyclone matches a ROS endpoint
with ours by type *name* only (XTypes 7.6.3.4.2); the TypeInformation derived from the
IdlStruct declarations (fxis_shm.ros2.idltypes) only matters to XTypes-aware peers such as our test peer.

Raw CDR: ``cyclonedds._clayer.ddspy_write`` takes any C-contiguous buffer and calls
``dds_write``; Cyclone copies it once and validates it against the type's CDR ops, so a
malformed buffer is refused (``DDSException``) instead of going on the wire. The binding's own
``DataWriter.write`` would serialize element by element and copy again; we skip both.
``ddspy_write`` is private API: the ``ros2`` extra pins cyclonedds to 11.0.x for it.

``ddspy_write`` holds the GIL for the whole ``dds_write``, and a reliable writer may block in
it up to RELIABILITY.max_blocking_time when its readers lag: hence ``CAMERA_PUBLISHER``'s
100 ms (rmw uses infinity).
"""

import time
from dataclasses import replace
from typing import Any

from cyclonedds._clayer import ddspy_take, ddspy_write, ddspy_write_ts
from cyclonedds.core import (
    DDSException,
    DDSStatus,
    Entity,
    InstanceState,
    ReadCondition,
    SampleState,
    ViewState,
    WaitSet,
)
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from fxis_shm.formats import cdr
from fxis_shm.formats.rosnames import dds_topic_name
from fxis_shm.ros2.endpoints import CAMERA_PUBLISHER, DEFAULT_SUBSCRIBER, HEADER, STRING, QosProfile, decode_requests
from fxis_shm.ros2.idltypes import IDL_TYPES, TYPE_HASHES, check_ros_compatible
from fxis_shm.ros2.matching import MatchTable, TopicMatches

# Cyclone's dds_qos_policy_id_t, as *_incompatible_qos statuses report the policy that failed.
RELIABILITY_QOS_POLICY_ID = 11
DATA_REPRESENTATION_QOS_POLICY_ID = 25
QOS_POLICY_NAMES = {
    2: "DURABILITY",
    3: "PRESENTATION",
    4: "DEADLINE",
    5: "LATENCY_BUDGET",
    6: "OWNERSHIP",
    8: "LIVELINESS",
    10: "PARTITION",
    RELIABILITY_QOS_POLICY_ID: "RELIABILITY",
    12: "DESTINATION_ORDER",
    13: "HISTORY",
    24: "TYPE_CONSISTENCY",
    DATA_REPRESENTATION_QOS_POLICY_ID: "DATA_REPRESENTATION",
}


def cyclone_qos(profile: QosProfile, user_data: bytes | None = None) -> Qos:
    """The Cyclone QoS rmw_cyclonedds' ``create_readwrite_qos`` makes of ``profile``."""
    if not profile.reliable:
        reliability: Any = Policy.Reliability.BestEffort
    elif profile.max_blocking_ms is None:
        reliability = Policy.Reliability.Reliable(max_blocking_time=duration(infinite=True))
    else:
        reliability = Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=profile.max_blocking_ms))
    policies: list[Any] = [
        reliability,
        Policy.History.KeepLast(profile.depth),
        Policy.Durability.TransientLocal if profile.transient_local else Policy.Durability.Volatile,
        Policy.WriterDataLifecycle(autodispose=False),
        Policy.Liveliness.Automatic(lease_duration=duration(infinite=True)),
        Policy.DataRepresentation(use_cdrv0_representation=True),  # XCDR1 only, as rmw
    ]
    if user_data is not None:
        policies.append(Policy.Userdata(user_data))
    return Qos(*policies)


# What every rmw publishes its nodes' endpoints on (rmw_dds_common's graph cache reads it).
GRAPH_TOPIC, GRAPH_TYPE = "ros_discovery_info", "rmw_dds_common/msg/ParticipantEntitiesInfo"
GRAPH_PUBLISHER = QosProfile(reliable=True, depth=1, transient_local=True)


def _delete_now(entity: Entity) -> None:
    """Delete a cyclonedds entity and its children now (sockets freed), not whenever GC runs."""
    if Entity._entities.get(entity._ref) is entity:
        del Entity._entities[entity._ref]
        entity._delete(entity._ref)


def _typehash_user_data(ros_type: str) -> bytes:
    type_hash = TYPE_HASHES.get(ros_type)
    return f"typehash={type_hash};".encode() if type_hash else b""


class RosParticipant:
    """One DDS participant that looks like an rmw_cyclonedds context; a context manager.

    ``config``: Cyclone XML, applied by creating the ``Domain`` explicitly, so nothing global
    (``CYCLONEDDS_URI``) is touched; None: Cyclone reads ``CYCLONEDDS_URI`` as usual. A process
    can hold only one explicitly configured domain per id: share the participant. ``close``
    deletes the participant, its readers and writers, and that domain.
    """

    VIA = "cyclone"

    def __init__(self, domain_id: int, config: str | None = None, enclave: str = "/") -> None:
        self.domain_id = domain_id
        self.domain: Domain | None = Domain(domain_id, config) if config is not None else None
        self.participant = DomainParticipant(domain_id, qos=Qos(Policy.Userdata(f"enclave={enclave};".encode())))
        self._topics: dict[tuple[str, str], Topic] = {}
        self.matches = MatchTable()  # per topic: who matched, who could not and why
        self._closed = False
        self._node: cdr.NodeEntities | None = None
        self._graph: RawWriter | None = None

    def topic(self, ros_topic: str, ros_type: str, *, dds_name: str | None = None) -> Topic:
        """The DDS topic of (ROS topic, ROS type), made once per participant; ``dds_name`` for a
        topic outside ROS's naming (``ros_discovery_info``)."""
        key = (ros_topic, ros_type)
        if key not in self._topics:
            idl = IDL_TYPES[ros_type]
            check_ros_compatible(idl, ros_type)
            self._topics[key] = Topic(self.participant, dds_name or dds_topic_name(ros_topic), idl)
        return self._topics[key]

    def announce_node(self, name: str, namespace: str) -> None:
        """Be node ``namespace/name`` on the ROS graph (``ros2 node list``, ``rqt_graph``): publish
        on ``ros_discovery_info`` which of this participant's endpoints belong to it, as every
        rmw does, again each time an endpoint is added."""
        self._node = cdr.NodeEntities(namespace or "/", name)
        self._graph = RawWriter(self, GRAPH_TOPIC, GRAPH_TYPE, GRAPH_PUBLISHER, dds_name=GRAPH_TOPIC)
        self._announce()

    def _added(self, endpoint: str, guid: bytes) -> None:
        """An endpoint of the node was made: say so on the graph topic."""
        if self._node is None:
            return
        readers, writers = list(self._node.readers), list(self._node.writers)
        (readers if endpoint == "reader" else writers).append(guid)
        self._node = replace(self._node, readers=readers, writers=writers)
        self._announce()

    def _announce(self) -> None:
        if self._graph is not None and self._node is not None:
            gid = self.participant.guid.bytes
            self._graph.write(cdr.encode_participant_entities_info(gid, [self._node], pad=True))

    def writer(self, ros_topic: str, ros_type: str, profile: QosProfile | None = None) -> "RawWriter":
        """A :class:`RawWriter`, with :data:`CAMERA_PUBLISHER` unless told otherwise."""
        return RawWriter(self, ros_topic, ros_type, profile or CAMERA_PUBLISHER)

    def raw_reader(self, ros_topic: str, ros_type: str, profile: QosProfile | None = None) -> "RawReader":
        """A :class:`RawReader`, with :data:`DEFAULT_SUBSCRIBER` unless told otherwise."""
        return RawReader(self, ros_topic, ros_type, profile or DEFAULT_SUBSCRIBER)

    def header_reader(self, ros_topic: str, profile: QosProfile | None = None) -> "RequestReader":
        """A :class:`RequestReader` of Headers, with :data:`DEFAULT_SUBSCRIBER` unless told otherwise."""
        return RequestReader(self, ros_topic, HEADER, profile or DEFAULT_SUBSCRIBER)

    def string_reader(self, ros_topic: str, profile: QosProfile | None = None) -> "RequestReader":
        """A :class:`RequestReader` of Strings (JSON requests)."""
        return RequestReader(self, ros_topic, STRING, profile or DEFAULT_SUBSCRIBER)

    def close(self) -> None:
        """Delete the participant (with its readers and writers) and its domain now; idempotent."""
        if self._closed:
            return
        self._closed = True
        self._topics.clear()
        _delete_now(self.participant)
        if self.domain is not None:
            _delete_now(self.domain)

    def __enter__(self) -> "RosParticipant":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class RawWriter:
    """Publishes pre-built XCDR1 messages of one (ROS topic, ROS type).

    A write costs no Python serialization: one memcpy and a validation inside Cyclone, then
    the transport.
    """

    def __init__(
        self, node: RosParticipant, ros_topic: str, ros_type: str, profile: QosProfile, *, dds_name: str | None = None
    ) -> None:
        self.ros_topic, self.ros_type = ros_topic, ros_type
        qos = cyclone_qos(profile, _typehash_user_data(ros_type))
        self._writer = DataWriter(node.participant, node.topic(ros_topic, ros_type, dds_name=dds_name), qos=qos)
        self._ref: int = self._writer._ref
        # A change of the matched readers wakes wait_for_readers (reading the status re-arms it).
        self._writer.set_status_mask(DDSStatus.PublicationMatched)
        self._match_changes = WaitSet(node.participant)
        self._match_changes.attach(self._writer)
        matches = node.matches.of(ros_topic)
        matches.counter = self.matched_count
        matches.poll = self._poll_refusals
        if dds_name is None:  # the graph topic is not one of the node's own
            node._added("writer", self._writer.guid.bytes)

    def _poll_refusals(self, matches: TopicMatches) -> None:
        total, policy_id = self.incompatible_qos()
        if total:
            policy = QOS_POLICY_NAMES.get(policy_id, f"policy {policy_id}")
            others = sum(count for name, count in matches.qos_refusals.items() if name != policy)
            matches.qos_refusals[policy] = total - others

    def write(self, payload: bytes | bytearray | memoryview, timestamp_ns: int | None = None) -> None:
        """Publish one serialized message (encapsulation header included); DDSException if
        Cyclone refuses it (malformed CDR) or the writer is gone.

        ``payload`` should be padded to a multiple of 4 bytes (``cdr.encode_*(..., pad=True)``),
        else it is padded here at the cost of a copy. ``timestamp_ns``: the DDS source
        timestamp (ROS's ``MessageInfo.source_timestamp``); None: now.
        """
        if memoryview(payload).nbytes % 4:
            payload = cdr.pad4(bytes(payload))
        if timestamp_ns is None:
            ret = ddspy_write(self._ref, payload)
        else:
            ret = ddspy_write_ts(self._ref, payload, timestamp_ns)
        if ret < 0:
            raise DDSException(ret, f"dds_write on {self.ros_topic} ({self.ros_type})")

    def matched_count(self) -> int:
        """Readers matched now (PUBLICATION_MATCHED.current_count)."""
        return int(self._writer.get_publication_matched_status().current_count)

    def incompatible_qos(self) -> tuple[int, int]:
        """(total_count, last_policy_id) of OFFERED_INCOMPATIBLE_QOS: readers refused, and why."""
        status = self._writer.get_offered_incompatible_qos_status()
        return int(status.total_count), int(status.last_policy_id)

    def wait_for_readers(self, n: int = 1, timeout: float = 5.0) -> bool:
        """Block until at least ``n`` readers match, at most ``timeout`` s; whether they did."""
        deadline = time.monotonic() + timeout
        while self.matched_count() < n:
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            self._match_changes.wait(duration(seconds=left))
        return True

    def wait_for_acks(self, timeout: float = 5.0) -> bool:
        """Block until the reliable readers acknowledged everything written (at most ``timeout``
        s); True at once for best effort."""
        return bool(self._writer.wait_for_acks(duration(seconds=timeout)))


class RawReader:
    """Reads one (ROS topic, ROS type) as the serialized CDR bytes, decoded by the caller
    (fxis_shm.formats.cdr): no per-element Python deserialization, whatever the size."""

    _ANY = SampleState.Any | ViewState.Any | InstanceState.Any

    def __init__(self, node: RosParticipant, ros_topic: str, ros_type: str, profile: QosProfile) -> None:
        self.ros_topic, self.ros_type = ros_topic, ros_type
        qos = cyclone_qos(profile, _typehash_user_data(ros_type))
        self._reader = DataReader(node.participant, node.topic(ros_topic, ros_type), qos=qos)
        self._waitset = WaitSet(node.participant)
        self._waitset.attach(ReadCondition(self._reader, self._ANY))
        node.matches.of(ros_topic).counter = self.matched_count
        node._added("reader", self._reader.guid.bytes)

    def take_raw(self, max_samples: int = 64) -> list[tuple[bytes, int]]:
        """Without blocking: what has arrived, as (CDR bytes, source timestamp ns)."""
        ret = ddspy_take(self._reader._ref, self._ANY, max_samples)
        if isinstance(ret, int):
            raise DDSException(ret, f"take on {self.ros_topic}")
        return [(data, int(info.source_timestamp)) for data, info in ret if info.valid_data]

    def wait_raw(self, timeout: float) -> list[tuple[bytes, int]]:
        """Block up to ``timeout`` s for messages, then take them (may be [])."""
        received = self.take_raw()
        if received:
            return received
        self._waitset.wait(duration(seconds=timeout))
        return self.take_raw()

    def matched_count(self) -> int:
        """Writers matched now (SUBSCRIPTION_MATCHED.current_count)."""
        return int(self._reader.get_subscription_matched_status().current_count)


class RequestReader(RawReader):
    """Reads requests (``std_msgs/msg/Header`` or ``String``), decoded by ``cdr``
    (:func:`fxis_shm.ros2.endpoints.decode_requests`).

    Reliable by default, so that no request is lost: it then does not match a best-effort
    publisher (``ros2 topic pub --qos-reliability best_effort``); ``ros2 topic pub``, rclpy
    and rclcpp publish reliably unless told otherwise.
    """

    def take(self, max_samples: int = 64) -> list[Any]:
        """Without blocking: what has arrived (malformed messages are dropped)."""
        return decode_requests(self.ros_type, self.take_raw(max_samples))

    def wait(self, timeout: float) -> list[Any]:
        """Block up to ``timeout`` s for messages, then take them (may be [])."""
        return decode_requests(self.ros_type, self.wait_raw(timeout))
