"""The contenders bench/compare/peers.py times fxis against: imagezmq (a hub in a child process),
a multiprocessing.Queue server, the two floors, a plain copy and a copy into reused buffers,
and the floor of fxis's own network design: a bare ZeroMQ reply carrying the frames copied once.

Each contender moves the frames of a "source" tuple (copies taken from the service once).
"""

from __future__ import annotations

import contextlib
import queue
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from bench.shared.interleave import Contender, cycle

IMZ, IMZ_PER_IMAGE, IMZ_1 = "imagezmq", "imagezmq per image (sample / N)", "imagezmq 1 image"
MPQ, COPY, REUSED = "mp.Queue", "plain copy (fresh arrays)", "copy into reused buffers"
COPY_CONTROL = "plain copy, ipc phase (control)"
ZMQ_FLOOR = "ZeroMQ reply, frames copied once"
CHILD_START_S = 30.0


# ---- child processes: the imagezmq hub, the multiprocessing.Queue server, the ZeroMQ floor ----


def hub_main(address: str, ready) -> None:
    """An ImageHub that answers every image with b"OK" (runs in a child process)."""
    import imagezmq

    hub = imagezmq.ImageHub(open_port=address)
    ready.set()
    while True:
        hub.recv_image()
        hub.send_reply(b"OK")


def queue_server_main(source: list[list[np.ndarray]], requests, replies, ready) -> None:
    """For each (id, k) request, puts (id, the frames of source tuple k) on ``replies``."""
    ready.set()
    while True:
        req = requests.get()
        if req is None:
            return
        req_id, k = req
        replies.put((req_id, source[k % len(source)]))


def floor_main(address: str, source: list[list[np.ndarray]], ready) -> None:
    """A ROUTER that answers every request with the next source tuple as the coordinator sends a
    reply: a small header, then each frame copied once into its message with the coordinator's
    own copy and malloc setting (nothing else: no request decoding, no choosing, no seqlock),
    over the same transport."""
    import zmq

    from fxis_shm.service.coordinator import as_message, keep_message_memory

    keep_message_memory()  # as the coordinator: a copy lands in memory malloc kept, not fresh pages
    sock = zmq.Context().socket(zmq.ROUTER)
    sock.bind(address)
    ready.set()
    k = 0
    while True:
        envelope = sock.recv_multipart()[:-1]
        frames = source[k % len(source)]
        k += 1
        sock.send_multipart(envelope + [b"{}"] + [as_message(f) for f in frames])


@contextlib.contextmanager
def child(ctx, target: Callable, *args) -> Any:
    """A daemon child process running ``target(*args, ready)``, started when it says it is
    ready, terminated (then killed) on exit whatever happened."""
    ready = ctx.Event()
    proc = ctx.Process(target=target, args=(*args, ready), daemon=True)
    proc.start()
    try:
        deadline = time.monotonic() + CHILD_START_S
        while not ready.wait(0.1):
            if proc.exitcode is not None:
                raise RuntimeError(f"{target.__name__} exited with code {proc.exitcode} during start-up")
            if time.monotonic() > deadline:
                raise RuntimeError(f"{target.__name__} did not start within {CHILD_START_S:.0f} s")
        yield proc
    finally:
        proc.terminate()
        proc.join(5)
        if proc.is_alive():
            proc.kill()
            proc.join(5)


class TimedSender:
    """imagezmq.ImageSender whose REQ socket gives up after ``timeout`` s (then it is rebuilt:
    a REQ socket that missed its reply cannot send again)."""

    def __init__(self, address: str, timeout: float):
        self.address, self.timeout = address, timeout
        self.sender = None
        self._open()

    def _open(self) -> None:
        import imagezmq
        import zmq

        self.sender = imagezmq.ImageSender(connect_to=self.address)
        for opt, value in (
            (zmq.RCVTIMEO, int(self.timeout * 1000)),
            (zmq.SNDTIMEO, int(self.timeout * 1000)),
            (zmq.LINGER, 0),
        ):
            self.sender.zmq_socket.setsockopt(opt, value)

    def send(self, images: list[np.ndarray]) -> None:
        import zmq

        for j, image in enumerate(images):
            try:
                reply = self.sender.send_image(f"cam{j}", image)
            except zmq.Again:
                self.close()
                self._open()
                raise TimeoutError(f"imagezmq hub gave no reply within {self.timeout:g} s") from None
            if reply != b"OK":
                raise RuntimeError(f"imagezmq hub replied {reply!r}")

    def close(self) -> None:
        if self.sender is not None:
            self.sender.close()
            self.sender = None


class QueueClient:
    """Asks the queue server for a source tuple; a late reply to an earlier request is skipped."""

    def __init__(self, requests, replies, timeout: float):
        self.requests, self.replies, self.timeout = requests, replies, timeout
        self._id = 0

    def get(self, k: int) -> list[np.ndarray]:
        self._id += 1
        self.requests.put((self._id, k))
        deadline = time.monotonic() + self.timeout
        while True:
            try:
                req_id, frames = self.replies.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise TimeoutError(f"mp.Queue server gave no reply within {self.timeout:g} s") from None
            if req_id == self._id:
                return frames


# ---- the contenders ---------------------------------------------------------------------------


def frames_check(n: int, shape: tuple) -> Callable[[Any], None]:
    def check(images):
        if len(images) != n or any(im.shape != shape for im in images):
            raise AssertionError(f"got {len(images)} images of {[im.shape for im in images]}, expected {n} of {shape}")

    return check


def copy_contenders(source: list[list[np.ndarray]], name: str = COPY) -> list[Contender]:
    """The two floors: fresh copies, and copies into buffers allocated (and faulted) once."""
    n, shape = len(source[0]), source[0][0].shape
    fresh_next, reused_next = cycle(source), cycle(source)
    dest = [np.zeros_like(f) for f in source[0]]

    def fresh():
        return [f.copy() for f in fresh_next()]

    def reused():
        for d, f in zip(dest, reused_next()):
            np.copyto(d, f)
        return dest

    return [Contender(name, fresh, frames_check(n, shape)), Contender(REUSED, reused, frames_check(n, shape))]


def imagezmq_contenders(sender: TimedSender, source: list[list[np.ndarray]]) -> list[Contender]:
    tuples_next = cycle(source)
    images_next = cycle([f for tup in source for f in tup])
    return [Contender(IMZ, lambda: sender.send(tuples_next())), Contender(IMZ_1, lambda: sender.send([images_next()]))]


def floor_contender(address: str, source: list[list[np.ndarray]], timeout: float) -> Contender:
    """One sample: a request to floor_main, and the reply's frames as arrays (views of the
    received buffers, as a network reply's images are)."""
    import zmq

    sock = zmq.Context.instance().socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.connect(address)
    shape, dtype = source[0][0].shape, source[0][0].dtype

    def ask() -> list[np.ndarray]:
        sock.send_multipart([b"", b"{}"])
        if not sock.poll(timeout * 1000):
            raise TimeoutError(f"the ZeroMQ floor gave no reply within {timeout:g} s")
        reply = sock.recv_multipart(copy=False)
        return [np.frombuffer(f.buffer, dtype).reshape(shape) for f in reply[2:]]

    return Contender(ZMQ_FLOOR, ask, frames_check(len(source[0]), shape))


def queue_contender(qc: QueueClient, source: list[list[np.ndarray]]) -> Contender:
    index_next = cycle(list(range(len(source))))
    return Contender(MPQ, lambda: qc.get(index_next()), frames_check(len(source[0]), source[0][0].shape))
