"""The coordinator's end of the command path to its camera workers (docs/design.md, "Commands
to a camera worker"): one DEALER socket per worker, connected to the ipc endpoint the worker
binds (fxis_shm.shm.naming.command_endpoint).

The coordinator's poll loop never waits on a worker: ``send`` queues a command with a
deadline and returns, ``drain`` hands each reply to its callback, and ``expire`` fails the
commands whose deadline passed. The deadline travels with the command, so a worker that
takes it late (it was restarting) drops it instead of applying a change its caller was told
had failed. ZMQ_IMMEDIATE: a command to a worker that is not there fails at once.

A link is up once ZeroMQ has connected it and completed its handshake, which happens in
ZeroMQ's own thread some time after ``connect``: a monitor socket per link says when
(``drain_monitor``), so that the coordinator's own questions (the settings at start, after a
worker's restart) wait for it rather than fail and log that a running worker is not running.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Callable
from dataclasses import dataclass

import zmq
from zmq.utils.monitor import recv_monitor_message

from fxis_shm.core import timebase
from fxis_shm.errors import Code, ProtocolError
from fxis_shm.shm import naming
from fxis_shm.wire import commands

log = logging.getLogger("coordinator")

# (result or None, error code or None, error message or None)
Done = Callable[[dict[str, object] | None, str | None, str | None], None]


@dataclass
class _Pending:
    camera: str
    deadline: int  # ns of the service's clock
    done: Done


class WorkerLinks:
    def __init__(self, ctx: zmq.Context[zmq.Socket[bytes]], service: str, cameras: list[str]):
        self.sockets: dict[str, zmq.Socket[bytes]] = {}
        self.monitors: dict[zmq.Socket[bytes], str] = {}  # a link's monitor -> its camera
        self.up: set[str] = set()  # the cameras whose link is connected now
        for name in cameras:
            sock = ctx.socket(zmq.DEALER)
            sock.setsockopt(zmq.LINGER, 0)
            sock.setsockopt(zmq.IMMEDIATE, 1)  # no queueing for a worker that is not connected
            sock.setsockopt(zmq.RECONNECT_IVL, 100)
            monitor = sock.get_monitor_socket(zmq.EVENT_HANDSHAKE_SUCCEEDED | zmq.EVENT_DISCONNECTED)
            monitor.setsockopt(zmq.LINGER, 0)
            self.monitors[monitor] = name
            sock.connect(naming.command_endpoint(service, name))
            self.sockets[name] = sock
        self._pending: dict[int, _Pending] = {}
        self._ids = itertools.count(1)

    def send(self, camera: str, cmd: str, timeout_s: float, done: Done, **fields: object) -> None:
        """Send ``cmd`` to the camera's worker; ``done`` is called once, from ``drain`` or
        ``expire`` (or now, if the worker cannot be reached)."""
        command_id = next(self._ids)
        deadline = timebase.now() + int(timeout_s * 1e9)
        frame = commands.encode_command(command_id, cmd, deadline=deadline, **fields)
        try:
            self.sockets[camera].send_multipart([b"", frame], zmq.NOBLOCK)
        except zmq.Again:
            why = "its link's queue is full" if camera in self.up else "its worker is not running"
            done(None, Code.CAMERA_DOWN, f"camera {camera!r} takes no commands now: {why}")
            return
        self._pending[command_id] = _Pending(camera, deadline, done)

    def drain_monitor(self, monitor: zmq.Socket[bytes]) -> list[str]:
        """Note what a link's monitor says; the cameras whose link came up (a worker started,
        or restarted and linked again)."""
        came: list[str] = []
        camera = self.monitors[monitor]
        while monitor.poll(0):
            event = recv_monitor_message(monitor)["event"]
            if event == zmq.EVENT_HANDSHAKE_SUCCEEDED:
                self.up.add(camera)
                came.append(camera)
            elif event == zmq.EVENT_DISCONNECTED:
                self.up.discard(camera)
        return came

    def drain(self, sock: zmq.Socket[bytes]) -> None:
        while sock.poll(0):
            frames = sock.recv_multipart()
            try:
                reply = commands.decode_reply(frames[-1])
            except ProtocolError as exc:
                log.warning("a camera worker sent an unreadable reply: %s", exc.message)
                continue
            command_id = reply.get("id")
            pending = self._pending.pop(command_id, None) if isinstance(command_id, int) else None
            if pending is None:
                continue  # expired already: its caller was answered
            result, code, error = reply.get("result"), reply.get("code"), reply.get("error")
            if reply["ok"]:
                pending.done(result if isinstance(result, dict) else {}, None, None)
            else:
                pending.done(None, code if isinstance(code, str) and code else Code.INTERNAL, str(error or ""))

    def expire(self, now: int) -> None:
        for command_id, pending in list(self._pending.items()):
            if now >= pending.deadline:
                del self._pending[command_id]
                pending.done(
                    None, Code.TIMEOUT, f"camera {pending.camera!r}'s worker did not answer in time (is it restarting?)"
                )

    def next_deadline(self) -> int | None:
        return min((p.deadline for p in self._pending.values()), default=None)

    def close(self) -> None:
        for sock in self.sockets.values():
            sock.disable_monitor()
            sock.close()
        for monitor in self.monitors:
            monitor.close()
