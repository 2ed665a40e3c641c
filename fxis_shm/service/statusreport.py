"""The coordinator's answers about the service itself, given at once and never waiting for a
frame: ``status`` (docs/protocol.md 7.2), ``time`` (7.1) and ``frames`` (7.5a)."""

from __future__ import annotations

import json
from typing import TypeVar

from fxis_shm.core import timebase
from fxis_shm.core.engine import RequestEngine
from fxis_shm.errors import Code, ProtocolError
from fxis_shm.service import realtime
from fxis_shm.service.childspec import CoordinatorSpec
from fxis_shm.service.fastanswers import FastAnswers
from fxis_shm.service.outbox import Request
from fxis_shm.service.settingsdesk import SettingsDesk
from fxis_shm.service.streams import Streams
from fxis_shm.shm import naming, ordering
from fxis_shm.shm.cameras import FRAME_FIELDS, CameraHandle
from fxis_shm.shm.copyout import CopyOut
from fxis_shm.shm.localpath import boot_id, time_namespace
from fxis_shm.wire.statusdoc import CameraStatus, ProcessState, Ros2State, StatusDocument, SupervisorState

_State = TypeVar("_State", SupervisorState, Ros2State)


class ServiceReports:
    """Builds the replies of the ops that read the service's state: the status document from
    the counters of the parts that keep them, the supervisor's process table and the settings
    desk's reports; the clock; every camera's frame times."""

    def __init__(
        self,
        spec: CoordinatorSpec,
        clock: timebase.Clock,
        engine: RequestEngine,
        copyout: CopyOut,
        desk: SettingsDesk,
        streams: Streams,
        fast: FastAnswers | None,
    ):
        self.spec, self.clock, self.engine, self.copyout = spec, clock, engine, copyout
        self.cameras: dict[str, CameraHandle] = copyout.cameras
        self.desk, self.streams, self.fast = desk, streams, fast
        self.started_ns = clock.now_ns()
        self.boot_id = boot_id()
        self.time_namespace = time_namespace()

    def status(self, requests_served: int, events_dropped: int) -> StatusDocument:
        """The ``status`` reply's body, now."""
        now = self.clock.now_ns()
        supervisor = realtime.with_scheduling(self._state_of("supervisor", SupervisorState))
        processes = supervisor["processes"] if supervisor is not None else {}
        return {
            "op": "status",
            "service": self.spec.service,
            "now": now,
            "boot_id": self.boot_id,
            "time_namespace": self.time_namespace,
            "clock": timebase.wire_name(),  # the header's spelling (issue 43)
            "encoded": self.copyout.encoded.status(),
            "ring_ordering": ordering.MODE,
            "uptime_s": round((now - self.started_ns) / 1e9, 3),
            "endpoint": self.spec.endpoint,
            "pub": self.spec.pub,
            "events": self.spec.events,
            "pending": len(self.engine.pending),
            "requests_served": requests_served,
            "requests_compiled": self.fast.answered if self.fast is not None else 0,
            "events_dropped": events_dropped,
            "streams": self.streams.status(),
            "supervisor": supervisor,
            "ros2": self._state_of("ros2", Ros2State),
            "settings": self.engine.settings,
            "cameras": {name: self._camera(name, cam, now, processes) for name, cam in self.cameras.items()},
        }

    def _camera(self, name: str, cam: CameraHandle, now: int, processes: dict[str, ProcessState]) -> CameraStatus:
        """A camera's entry: its handle's report, its worker's restarts and scheduling, and the
        settings and PTP state its worker last reported."""
        info: CameraStatus = cam.status(now)
        process = processes.get(f"camera:{name}")
        info["restarts"] = process.get("restarts") if process is not None else None
        info["sched"] = process.get("sched") if process is not None else None
        settings = self.desk.values(name, _generation(info))
        info["settings"] = settings
        if info.get("trigger") == "software" and info.get("fps") is None:  # captures on request: its set rate
            info["fps"] = (settings or {}).get("fps")
        info["ptp"] = self.desk.ptp(name)  # None: the camera cannot say (or not yet asked)
        return info

    def _state_of(self, process: str, shape: type[_State]) -> _State | None:
        """What the supervisor or the ROS 2 bridge last reported, of that ``shape`` (None: nothing)."""
        try:
            with open(naming.state_path(self.spec.service, process)) as f:
                state: _State = json.load(f)
        except (OSError, ValueError):
            return None
        return state

    def time(self, t_received: int) -> Request:
        """The clock now, and when the request was received: a caller estimating our clock
        against its own takes both (an NTP-style exchange of four timestamps)."""
        return {"op": "time", "received": t_received, "now": self.clock.now_ns(), "boot_id": self.boot_id}

    def frames(self, request: Request) -> Request:
        """Every camera's frame times without pixels, for callers that choose frames
        themselves (a client over several services)."""
        names = request["cameras"] or list(self.cameras)
        unknown = [n for n in names if n not in self.cameras]
        if unknown:
            raise ProtocolError(f"unknown camera(s) {unknown}; known: {sorted(self.cameras)}", Code.UNKNOWN_CAMERA)
        now = self.clock.now_ns()
        return {
            "op": "frames",
            "now": now,
            "columns": list(FRAME_FIELDS),
            "cameras": {n: self.cameras[n].timeline(now) for n in names},
        }


def _generation(info: CameraStatus) -> int | None:
    generation = info.get("generation")
    return generation if isinstance(generation, int) else None
