"""The coordinator's compiled answer to the common requests: an image or a tuple at a given t*,
or the latest frames, raw. The C reader of the rings (fxis_shm.shm.fastpick) looks and decides
as the engine would; each chosen frame is copied once, straight into the message that carries
it, under the seqlock (as the engine's replies are, fxis_shm.shm.copyout). Anything else, and
whatever the C reader does not settle, is the engine's (``answer`` returns None). The reply's
header is written from templates (fxis_shm.wire.replytext), the bytes the codec would write.

A request is answered here only where the engine would admit it: its limits on the requests
waiting in it (in all, and per client) hold as they did.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import zmq
from numpy.typing import NDArray

from fxis_shm.core import timebase
from fxis_shm.core.engine import RequestEngine
from fxis_shm.core.snapshot import CAPTURES
from fxis_shm.errors import Overwritten
from fxis_shm.service.outbox import Part, Request
from fxis_shm.shm import fastpick
from fxis_shm.shm.cameras import CameraHandle
from fxis_shm.shm.copyout import CopyOut, copied_by
from fxis_shm.wire import replytext
from fxis_shm.wire.encoding import RAW

_OPS = {"image": fastpick.IMAGE, "tuple": fastpick.TUPLE, "latest": fastpick.LATEST}


class FastAnswers:
    """``message(bytes)`` copies a frame into the transport's message (the coordinator's
    zmq.Frame); frames of more than ``message_max`` bytes are the engine's."""

    def __init__(
        self,
        cameras: dict[str, CameraHandle],
        engine: RequestEngine,
        copyout: CopyOut,
        message: Callable[[NDArray[Any]], zmq.Frame],
        message_max: int,
    ):
        self.cameras, self.engine, self.copyout = cameras, engine, copyout
        self.message, self.message_max = message, message_max
        self.picker: fastpick.Picker | None = None
        self.answered = 0  # requests answered here

    def answer(self, request: Request, t_received: int, client: object = None) -> list[Part] | None:
        """The reply (its header, written from templates, and its images), or None: the engine
        answers (or refuses: BUSY)."""
        op = _OPS.get(request["op"])
        if op is None or request.get("encoding") not in (None, RAW) or self.engine.busy(client):
            return None
        if request.get("max_skew_ms") is not None or request.get("capture"):  # (a capture: the engine schedules)
            return None
        picker = self._picker()
        if picker is None:
            return None
        cameras = request.get("cameras") if request.get("camera") is None else (request["camera"],)
        at = 0 if op == fastpick.LATEST else request.get("at")
        got = picker.pick(cameras, op, at, request.get("sync"), request.get("wait"), False, t_received)
        if got is None:
            return None
        _, t_decided, _, skew_ns, picked, indices, names = got
        frames: list[str] = []
        images: list[Part] = []
        waited: list[tuple[str, int]] = []
        for k, name, picked_frame in zip(indices, names, picked):
            slot, seq, frame_id, t_capture, t_stored, t_available, generation, t_target, capture, ready_at, _ = (
                picked_frame
            )
            reader = picker.readers[k]
            if reader.layout.nbytes > self.message_max:
                return None
            try:
                images.append(copied_by(reader, slot, seq, self.message))
            except Overwritten:
                self.cameras[name].torn_reads += 1
                return None
            header = self.copyout.header(name)
            frames.append(
                header.frame_json(
                    frame_id, t_capture, t_stored, generation, t_available, len(frames), t_target, CAPTURES[capture]
                )
            )
            waited.append((header.name_json, ready_at))
        t_copied = timebase.now()
        tuple_ = op == fastpick.TUPLE
        text = replytext.frames_reply(
            request["id"],
            request["op"],
            frames,
            (t_decided, t_received, t_received, t_copied, timebase.now()),
            waited,
            None if op == fastpick.LATEST else at,
            skew_ns if tuple_ else None,
            (request.get("sync") or self.engine.settings["sync"]) if tuple_ else None,
        )
        self.answered += 1
        return [text, *images]

    def _picker(self) -> fastpick.Picker | None:
        """The C reader of the rings open now (made again once a ring was replaced)."""
        if self.picker is None or self.picker.retired:
            self.picker = None
            readers = [handle.reader for handle in self.cameras.values() if handle.reader is not None]
            if len(readers) < len(self.cameras):
                return None
            self.picker = fastpick.Picker(
                list(self.cameras), readers, self.engine.settings, timebase.service_clock(), 0
            )
        return self.picker
