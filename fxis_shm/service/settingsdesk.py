"""The coordinator's side of the ``settings`` op (docs/protocol.md 7.8), so that no client can
starve a camera by asking (issue 42).

A read is answered here, from what the camera's worker last reported (it reports its values,
limits and generation with every change, and when asked once per new generation), never by
queueing a command in front of the frames. A change, or a read of the node map's features,
goes to the worker, which applies one command between two frames; at most ``CHANGES_LIMIT``
wait per camera, and beyond that the client gets ``BUSY`` at once. A flood therefore costs the
flooder its answers, not the camera its frames.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from fxis_shm.core import timebase
from fxis_shm.core.tuning import UNCHANGED
from fxis_shm.errors import Code, ProtocolError
from fxis_shm.service.logtally import LogTally
from fxis_shm.service.outbox import Part, Respond
from fxis_shm.service.workerlink import Done, WorkerLinks
from fxis_shm.shm.cameras import CameraHandle
from fxis_shm.wire import commands, protocol

log = logging.getLogger("coordinator")

CHANGES_LIMIT = 8  # changes (and feature lists) waiting for a camera's worker; beyond: BUSY
READERS_LIMIT = 64  # reads waiting for a worker's first report of a new generation; beyond: BUSY
REPORTED = ("values", "limits", "generation", "ptp")  # what a read answers with

Message = dict[str, Any]  # a request, a reply's body, a worker's report
# (respond, request, reply body): the coordinator's reply, counted and stamped
Answer = Callable[[Respond, Message, Message], None]


@dataclass
class _Camera:
    report: Message | None = None  # the worker's last report (REPORTED), None: none yet
    asking: bool = False  # a report asked for, not answered yet
    readers: list[tuple[Message, Respond]] = field(default_factory=list)  # reads waiting for it
    changes: int = 0  # changes sent to the worker, not answered yet


class SettingsDesk:
    def __init__(
        self,
        cameras: dict[str, CameraHandle],
        answer: Answer,
        publish: Callable[[str, Sequence[Part]], None],
        tally: LogTally,
        clock: timebase.Clock = timebase.REAL,
    ):
        self.cameras, self._answer, self._publish, self._tally = cameras, answer, publish, tally
        self.clock = clock  # the coordinator's (virtual in the harness)
        self._known = {name: _Camera() for name in cameras}
        self.links: WorkerLinks | None = None  # set when the coordinator's sockets are made

    def request(self, request: Message, respond: Respond) -> None:
        """Answer a ``settings`` request, now or when the worker has; ProtocolError for one
        that cannot be (unknown camera, BUSY, CAMERA_DOWN)."""
        camera = request["camera"]
        if camera not in self.cameras:
            raise ProtocolError(
                f"unknown camera {camera!r}; this service has {sorted(self.cameras)}", Code.UNKNOWN_CAMERA
            )
        if request["set"] is not None or request["features"]:
            self._check_up(camera)
            self._change(camera, request, respond)
        else:
            self._read(camera, request, respond)

    def _check_up(self, camera: str) -> None:
        """CAMERA_DOWN now for a camera whose worker is not running, as its ring shows: the
        link's own disconnect comes later (ZeroMQ notes it in its I/O thread), and a command
        queued on it meanwhile would wait out its timeout."""
        down = self.cameras[camera].down_reason(self.clock.now_ns())
        if down is not None:
            raise ProtocolError(down, Code.CAMERA_DOWN)

    def ask(self, camera: str) -> None:
        """Have the camera's worker report its settings (once: a report already asked for is
        not asked again). With nobody waiting for the answer (the coordinator's own question:
        at start, for status) and the worker's link not up yet, it is asked when the link comes
        up (``linked``) rather than told now that it cannot be reached."""
        known = self._known[camera]
        if known.asking or self.links is None:
            return
        if not known.readers and camera not in self.links.up:
            return  # linked() asks
        known.asking = True
        self.links.send(camera, commands.SETTINGS, commands.SETTINGS_TIMEOUT_S, self._reported(camera))

    def linked(self, camera: str) -> None:
        """The camera's worker (re)linked: a worker that just started or restarted, whose
        settings are asked now, so that reads and status have them from its first frames."""
        self.ask(camera)

    def values(self, camera: str, generation: int | None) -> Message | None:
        """For status: the values the worker reported for this generation of its frames; for
        another, the worker is asked again (None until it answers)."""
        report = self._known[camera].report
        if report is not None and generation in (report["generation"], None):
            values: Message = report["values"]
            return values
        if generation is not None:
            self.ask(camera)
        return None

    def ptp(self, camera: str) -> Message | None:
        report = self._known[camera].report
        ptp: Message | None = None if report is None else report.get("ptp")
        return ptp

    # ---- reads ----

    def _read(self, camera: str, request: Message, respond: Respond) -> None:
        self._check_up(camera)
        known = self._known[camera]
        ring = self.cameras[camera].reader
        if known.report is not None and ring is not None and known.report["generation"] == ring.field("generation"):
            self._answer(respond, request, {"op": "settings", "camera": camera, **known.report})
            return
        if len(known.readers) >= READERS_LIMIT:
            raise self._busy(camera, f"{READERS_LIMIT} reads of camera {camera!r} wait for its worker's report")
        known.readers.append((request, respond))
        self.ask(camera)

    def _reported(self, camera: str) -> Done:
        def done(result: Message | None, code: str | None, message: str | None) -> None:
            known = self._known[camera]
            known.asking = False
            readers, known.readers = known.readers, []
            if result is None:
                log.info("camera %s did not report its settings: %s", camera, message)
                for request, respond in readers:
                    respond(protocol.encode_error(request["id"], code or Code.INTERNAL, message or ""))
                return
            report = self._keep(camera, result)
            for request, respond in readers:
                self._answer(respond, request, {"op": "settings", "camera": camera, **report})

        return done

    # ---- changes ----

    def _change(self, camera: str, request: Message, respond: Respond) -> None:
        known = self._known[camera]
        if known.changes >= CHANGES_LIMIT:
            raise self._busy(
                camera,
                f"camera {camera!r} has {CHANGES_LIMIT} changes waiting for its worker, which applies one "
                "between two frames; try again after a back-off",
            )
        known.changes += 1

        def done(result: Message | None, code: str | None, message: str | None) -> None:
            known.changes -= 1
            if result is None:
                respond(protocol.encode_error(request["id"], code or Code.INTERNAL, message or ""))
                return
            self._keep(camera, result)
            self._answer(respond, request, {"op": "settings", "camera": camera, **result})

        fields = {k: request[k] for k in ("set", "features") if request[k] is not None}
        assert self.links is not None
        self.links.send(camera, commands.SETTINGS, commands.SETTINGS_TIMEOUT_S, done, **fields)

    def _keep(self, camera: str, result: Message) -> Message:
        """Keep a worker's report for reads and status, and announce a change (the log, and
        the event ``settings/CAMERA|`` on the publish endpoint); a change to the values the
        camera had is none. Returns the report kept."""
        report = self._known[camera].report = {key: result.get(key) for key in REPORTED}
        if result.get("cost", UNCHANGED) == UNCHANGED:
            return report
        text = f"camera {camera} changed {result['changed']} ({result['cost']})"
        for line in self._tally.note(f"changes of camera {camera}", text, self.clock.now_ns()):
            log.info("%s", line)
        event = {k: result[k] for k in ("changed", "cost", "values", "generation")}
        self._publish(f"settings/{camera}|", protocol.encode_reply(None, {"camera": camera, **event}))
        return report

    def _busy(self, camera: str, message: str) -> ProtocolError:
        for line in self._tally.note(f"BUSY settings of camera {camera}", message, self.clock.now_ns()):
            log.info("refused a settings request: %s", line)
        return ProtocolError(message, Code.BUSY)
