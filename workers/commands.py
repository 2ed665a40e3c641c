"""The camera worker's end of the command path (docs/design.md, "Commands to a camera worker").

The worker binds a ROUTER socket on ``ipc://`` under the service's commands folder (mode 0700;
the socket file 0600), so only the service's own user can reach it. A thread of its own
receives the coordinator's commands and queues them (at most ``INBOX_LIMIT``: beyond, BUSY at
once); the capture loop takes one between two frames (``take``), applies it and hands back its
reply (``reply``), which the thread sends. One a frame: a flood of commands slows the commands,
never the frames.
The sockets stay in their threads: the capture loop's side is a PAIR socket into the thread.
A worker that restarts binds the same path again, and the coordinator's DEALER reconnects.
"""

from __future__ import annotations

import logging
import os
import queue
import threading
from collections.abc import Callable, Mapping

import zmq

from fxis_shm.core import timebase
from fxis_shm.errors import Code, ProtocolError
from fxis_shm.shm import naming
from fxis_shm.wire import commands

log = logging.getLogger("camera")
_POLL_MS = 100  # how often the thread looks at the stop event when nothing arrives
# commands waiting for the capture loop; the coordinator sends at most 8 changes and 1 read a camera
INBOX_LIMIT = 16


class Command:
    """A command taken by the capture loop; ``reply`` (or ``fail``) once, from that loop's thread."""

    def __init__(self, server: CommandServer, envelope: list[bytes], body: dict):
        self._server, self._envelope, self.body = server, envelope, body

    def reply(self, result: dict) -> None:
        self._server.send(self._envelope, commands.encode_result(self.body["id"], result))

    def fail(self, code: str, message: str) -> None:
        self._server.send(self._envelope, commands.encode_failure(self.body["id"], code, message))


def private_folder(path: str) -> None:
    """Make ``path`` a folder only this user can enter (mode 0700), or refuse a foreign one."""
    os.makedirs(path, mode=0o700, exist_ok=True)
    info = os.stat(path)
    if info.st_uid != os.getuid():
        raise PermissionError(f"{path} belongs to another user (uid {info.st_uid}); remove it")
    os.chmod(path, 0o700)


class CommandServer:
    """``direct``: the commands this thread answers itself, at once (trigger_at, lockstep: a
    timer's business, not the capture loop's, which may sit in ``grab``); the others are queued."""

    def __init__(
        self,
        service: str,
        camera: str,
        stop: threading.Event,
        direct: Mapping[str, Callable[[dict], dict]] | None = None,
    ):
        self._direct = direct or {}
        self.endpoint = naming.command_endpoint(service, camera)
        path = self.endpoint[len("ipc://") :]
        private_folder(os.path.dirname(path))
        if os.path.exists(path):  # left by a worker that died: ours to replace (one worker per camera)
            os.unlink(path)
        self._ctx = zmq.Context()
        self._router = self._socket(zmq.ROUTER)
        self._router.bind(self.endpoint)
        os.chmod(path, 0o600)
        inner = f"inproc://replies-{id(self)}"
        self._replies_in = self._socket(zmq.PAIR)
        self._replies_in.bind(inner)
        self._replies_out = self._socket(zmq.PAIR)  # the capture loop's end
        self._replies_out.connect(inner)
        self._inbox: queue.Queue[Command] = queue.Queue(INBOX_LIMIT)
        self._stop = stop
        self._thread = threading.Thread(target=self._serve, daemon=True, name="commands")
        self._thread.start()

    def _socket(self, kind: int) -> zmq.Socket:
        sock = self._ctx.socket(kind)
        sock.setsockopt(zmq.LINGER, 0)
        return sock

    # ---- the capture loop's side ----

    def take(self) -> Command | None:
        """The oldest command waiting (None: none, at once)."""
        try:
            return self._inbox.get_nowait()
        except queue.Empty:
            return None

    def send(self, envelope: list[bytes], reply: bytes) -> None:
        self._replies_out.send_multipart([*envelope, reply])

    def close(self) -> None:
        self._stop.set()
        self._thread.join(1.0)
        self._replies_out.close()
        self._ctx.term()

    # ---- the thread ----

    def _serve(self) -> None:
        poller = zmq.Poller()
        poller.register(self._router, zmq.POLLIN)
        poller.register(self._replies_in, zmq.POLLIN)
        try:
            while not self._stop.is_set():
                ready = dict(poller.poll(_POLL_MS))
                if self._replies_in in ready:
                    while self._replies_in.poll(0):
                        self._router.send_multipart(self._replies_in.recv_multipart(), zmq.NOBLOCK)
                if self._router in ready:
                    while self._router.poll(0):
                        self._receive(self._router.recv_multipart())
        except zmq.ZMQError as exc:
            if not self._stop.is_set():
                log.error("the command socket failed: %s", exc)
        finally:
            self._router.close()
            self._replies_in.close()

    def _receive(self, frames: list[bytes]) -> None:
        split = frames.index(b"") + 1 if b"" in frames else 1
        envelope, body = frames[:split], frames[split:]
        try:
            if len(body) != 1:
                raise ProtocolError(f"a worker command is one frame, got {len(body)}")
            command = commands.decode_command(body[0])
        except ProtocolError as exc:
            self._router.send_multipart([*envelope, commands.encode_failure(None, exc.code, exc.message)])
            return
        handle = self._direct.get(command["cmd"])
        if handle is None:
            try:
                self._inbox.put_nowait(Command(self, envelope, command))
            except queue.Full:
                message = f"the camera worker has {INBOX_LIMIT} commands waiting (it applies one a frame)"
                self._router.send_multipart([*envelope, commands.encode_failure(command["id"], Code.BUSY, message)])
            return
        try:
            reply = commands.encode_result(command["id"], handle(command))
        except ProtocolError as exc:
            reply = commands.encode_failure(command["id"], exc.code, exc.message)
        except Exception as exc:  # a bug must not stop the commands
            log.exception("command %s failed", command["cmd"])
            reply = commands.encode_failure(command["id"], Code.INTERNAL, f"{type(exc).__name__}: {exc}")
        self._router.send_multipart([*envelope, reply])


def serve_pending(server: CommandServer | None, handle: Callable[[Command], dict]) -> None:
    """Apply the oldest command waiting, between two frames: it gets its result, or a clear
    error. At most one a call, so that the frames go on whatever number of commands comes."""
    command = _next_in_time(server) if server is not None else None
    if command is None:
        return
    try:
        command.reply(handle(command))
    except (ValueError, ProtocolError) as exc:  # refused: the camera keeps its settings
        code = getattr(exc, "code", Code.SETTING_REFUSED)
        command.fail(code, str(getattr(exc, "message", exc)))
    except Exception as exc:  # a bug must not stop the camera
        log.exception("command %s failed", command.body.get("cmd"))
        command.fail(Code.INTERNAL, f"{type(exc).__name__}: {exc}")


def _next_in_time(server: CommandServer) -> Command | None:
    """The oldest command whose deadline has not passed (the others are dropped: their callers
    were told they timed out)."""
    while (command := server.take()) is not None:
        deadline = command.body.get("deadline")
        if not isinstance(deadline, int) or timebase.now() <= deadline:
            return command
        log.warning("dropped a %s command that came after its deadline", command.body.get("cmd"))
    return None
