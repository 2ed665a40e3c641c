"""The shape of the ``status`` reply's body (docs/protocol.md 7.2), and of the process table the
supervisor writes for it, as ``TypedDict``s: types only, the document is the dict ``json`` makes.

Each camera's entry stays an open mapping: it is the camera handle's own report
(fxis_shm.shm.cameras.CameraHandle.status) with the coordinator's additions (``restarts``,
``sched``, ``settings``, ``ptp``), and which of its fields a camera has depends on its ring.
"""

from __future__ import annotations

from typing import TypedDict


class Scheduling(TypedDict):
    """A process's threads summed up (fxis_shm.service.rtpolicy.summary)."""

    policy: str | None  # the policy of its most urgent thread
    priorities: list[int]  # the real-time priorities in use, highest first
    rt_threads: int
    threads: int


class _ProcessBase(TypedDict):
    pid: int | None
    state: str
    restarts: int
    last_exit: int | None


class ProcessState(_ProcessBase, total=False):
    """One child process of the supervisor; ``sched`` is added for status (None once gone)."""

    sched: Scheduling | None


class SupervisorEvent(TypedDict):
    process: str
    t: int  # CLOCK_MONOTONIC, ns
    what: str


class SupervisorState(TypedDict):
    """The supervisor's process table, as it writes it for the coordinator (key: ``camera:NAME``,
    ``coordinator``, a viewer's role) with its last events."""

    pid: int
    processes: dict[str, ProcessState]
    events: list[SupervisorEvent]


class StreamCount(TypedDict):
    published: int  # messages published on the stream's topic so far


CameraStatus = dict[str, object]  # one camera's entry (see the module's docstring)
Ros2State = dict[str, object]  # the ROS 2 bridge's counters (fxis_shm.ros2.bridge.Bridge.status)


class StatusDocument(TypedDict):
    """The ``status`` reply's body: the service, its endpoints and counters, its processes,
    the ROS 2 bridge's counters and each camera's state."""

    op: str
    service: str
    now: int  # the service's clock, ns
    boot_id: str | None
    time_namespace: str | None
    clock: str
    encoded: dict[str, int]  # encoded: frames encoded, reused: encodings served again
    ring_ordering: str | None  # None: the rings cannot be read on this machine
    uptime_s: float
    endpoint: str
    pub: str
    events: str
    pending: int  # requests waiting in the engine
    requests_served: int
    requests_compiled: int  # of those, answered by the compiled reader
    events_dropped: int  # malformed request events with no topic to answer on
    streams: dict[str, StreamCount]  # topic -> its count
    supervisor: SupervisorState | None  # None: not written (yet)
    ros2: Ros2State | None  # None: no bridge
    settings: dict[str, object]  # the request defaults the configuration changed
    cameras: dict[str, CameraStatus]
