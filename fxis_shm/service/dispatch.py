"""Where each request the coordinator receives goes: a request from the request endpoint or a
request event (docs/protocol.md 15) is decoded, checked against who may ask it, and handed to
what answers it; for frames, the request engine decides (fxis_shm.core.engine) and what it
decides is carried out here: triggers fired, captures scheduled, frames copied out and sent."""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence

import zmq

from fxis_shm.core import timebase
from fxis_shm.core.engine import FRAME_OPS, Action, Failure, Pending, Reply, RequestEngine, Schedule, Trigger
from fxis_shm.errors import Code, Overwritten, ProtocolError
from fxis_shm.service.fastanswers import FastAnswers
from fxis_shm.service.logtally import LogTally
from fxis_shm.service.outbox import Outbox, Part, Request, Respond
from fxis_shm.service.serversockets import Access
from fxis_shm.service.settingsdesk import SettingsDesk
from fxis_shm.service.statusreport import ServiceReports
from fxis_shm.service.workerlink import Done, WorkerLinks
from fxis_shm.shm.copyout import MESSAGES, REFS, CopyOut
from fxis_shm.wire import commands, protocol

log = logging.getLogger("coordinator")

Received = bytes | zmq.Frame  # a part of a message received (a frame when its sender's key is asked)

FORBIDDEN_TEXT = (
    "this client may read settings but not change them: the service lets only the keys in its "
    "--curve-operators folder change them; ask its operator to add this client's public key (.key) "
    "there and restart the service, or use a key that is there"
)


def split_envelope(frames: Sequence[Received]) -> tuple[list[Part], list[Received]]:
    """ROUTER frames -> (routing envelope incl. the empty delimiter, body)."""
    for i in range(1, len(frames)):
        if len(frames[i]) == 0:
            return list(frames[: i + 1]), list(frames[i + 1 :])
    return list(frames[:1]), list(frames[1:])


def _bytes(part: Received | Part) -> bytes:
    """The bytes of a part received (a zmq.Frame's, kept by the frame: no second copy)."""
    return part.bytes if isinstance(part, zmq.Frame) else bytes(part)


def _readable_id(frame: Received) -> int | str | None:
    """The id of a request we could not decode, if it is there and readable."""
    value = _readable_field(frame, "id", (int, str))
    return value if isinstance(value, (int, str)) else None


def _readable_field(frame: Received, name: str, kinds: tuple[type, ...]) -> object:
    """A field of a header we could not decode, if it is there and readable."""
    try:
        value = json.loads(_bytes(frame)).get(name)
        return value if isinstance(value, kinds) and not isinstance(value, bool) else None
    except Exception:
        return None


class RequestDispatch:
    """Takes each received request or request event to what answers it (the settings desk, the
    service's reports, the compiled reader, the request engine) and carries out the engine's
    decisions; a request that cannot be answered gets its error, and nothing a client sends
    takes the service down. ``events_dropped`` counts events too malformed to answer."""

    def __init__(
        self,
        engine: RequestEngine,
        copyout: CopyOut,
        fast: FastAnswers | None,
        desk: SettingsDesk,
        reports: ServiceReports,
        outbox: Outbox,
        links: WorkerLinks,
        access: Access,
        tally: LogTally,
        clock: timebase.Clock,
    ):
        self.engine, self.copyout, self.fast, self.desk, self.reports = engine, copyout, fast, desk, reports
        self.outbox, self.links, self.access, self.tally, self.clock = outbox, links, access, tally, clock
        self.cameras = copyout.cameras
        self.events_dropped = 0

    def on_request(self, frames: Sequence[Received], t_received: int) -> None:
        """A request from the request endpoint (its ROUTER frames), received at ``t_received``."""
        envelope, body = split_envelope(frames)
        respond: Respond = lambda reply: self.outbox.send(envelope, reply)  # noqa: E731
        try:
            request = protocol.decode_request([_bytes(part) for part in body])
        except ProtocolError as exc:
            for line in self.tally.note("bad requests", f"bad request: {exc.message}", t_received):
                log.info("%s", line)
            rid = _readable_id(body[0]) if body else None
            respond(protocol.encode_error(rid, exc.code, exc.message))
            return
        if request["op"] == "settings" and request["set"] and not self.access.may_change(body[0]):
            respond(protocol.encode_error(request["id"], Code.FORBIDDEN, FORBIDDEN_TEXT))
            return
        self._start(request, respond, t_received, client=_bytes(envelope[0]))

    def on_event(self, frames: Sequence[Received], t_received: int) -> None:
        """A request event (its SUB frames): the reply is published on its ``reply_topic``."""
        try:
            request = protocol.decode_event([_bytes(part) for part in frames])
        except ProtocolError as exc:
            topic = _readable_field(frames[-1], "reply_topic", (str,)) if frames else None
            if isinstance(topic, str) and topic and not topic.startswith(protocol.RESERVED_TOPICS):
                rid = _readable_id(frames[-1])
                self.outbox.publish(topic, protocol.encode_error(rid, exc.code, exc.message))
            else:
                self.events_dropped += 1
            dropped = f"dropped a malformed request event: {exc.message}"
            for line in self.tally.note("malformed events", dropped, t_received):
                log.warning("%s", line)
            return
        topic = request["reply_topic"]
        self._start(request, lambda reply: self.outbox.publish(topic, reply), t_received)

    def _start(self, request: Request, respond: Respond, t_received: int, client: bytes | None = None) -> None:
        op = request["op"]
        try:
            if op == "settings":  # a read at once, a change when the camera's worker has applied it
                self.desk.request(request, respond)
                return
            if op not in FRAME_OPS:
                self.outbox.reply(respond, request, self._service_op(op, request, t_received))
                return
            local = self.reports.boot_id is not None and request.get("local") == self.reports.boot_id
            answer = self.fast.answer(request, t_received, client) if self.fast is not None and not local else None
            if answer is not None:  # (already encoded, "sent" stamped)
                self.outbox.requests_served += 1
                respond(answer)
                return
            self.carry_out(self.engine.submit(request, t_received, respond, client=client, local=local))
        except ProtocolError as exc:  # a request that cannot be answered as asked
            respond(protocol.encode_error(request["id"], exc.code, exc.message))
        except Exception as exc:  # a bug must not take the service down
            log.exception("internal error on %s", op)
            respond(protocol.encode_error(request["id"], Code.INTERNAL, repr(exc)))

    def _service_op(self, op: str, request: Request, t_received: int) -> Request:
        """The body of a reply about the service: status, time or (the codec admits no other op) frames."""
        if op == "status":
            return dict(self.reports.status(self.outbox.requests_served, self.events_dropped))
        if op == "time":
            return self.reports.time(t_received)
        return self.reports.frames(request)

    def carry_out(self, actions: list[Action]) -> None:
        """Do what the engine decided: fire triggers, copy frames out and reply, or fail."""
        for action in actions:
            if isinstance(action, Trigger):
                for cam in action.cameras:
                    self.cameras[cam].fire_trigger()
            elif isinstance(action, Schedule):
                self._schedule(action)
            elif isinstance(action, Failure):
                action.pending.ticket(protocol.encode_error(action.pending.id, action.code, action.message))
            else:
                self._answer(action)

    def _schedule(self, action: Schedule) -> None:
        """Have each camera's worker trigger it for a capture at ``action.t``; the first refusal
        fails the request (the engine waits for the frames captured for T meanwhile)."""
        for cam in action.cameras:
            self.links.send(
                cam, commands.TRIGGER_AT, commands.TRIGGER_TIMEOUT_S, self._scheduled(action.pending, cam), t=action.t
            )

    def _scheduled(self, pending: Pending, camera: str) -> Done:
        def done(result: dict[str, object] | None, code: str | None, message: str | None) -> None:
            if result is None:
                self.carry_out(self.engine.fail(pending, code or Code.INTERNAL, f"camera {camera!r}: {message}"))

        return done

    def _answer(self, reply: Reply) -> None:
        try:
            body, images = self.copyout.reply(reply, REFS if reply.pending.local else MESSAGES)
        except Overwritten:  # the ring came round during the copy: the engine plans again
            self.carry_out(self.engine.retry(reply, self.clock.now_ns()))
            return
        self.outbox.reply(reply.pending.ticket, reply.pending.request, body, images)
