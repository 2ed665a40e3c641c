"""Threads that turn each camera's "new frame" semaphore into a ZeroMQ message,
so the coordinator's single poll loop wakes on frames as it does on requests."""

from __future__ import annotations

import threading

import posix_ipc
import zmq

from fxis_shm.shm import naming

NOTIFY_ENDPOINT = "inproc://fxis-new-frames"
_WAIT_S = 0.2  # how often a watcher checks whether to stop, or re-opens a missing semaphore


def _watch(ctx: zmq.Context[zmq.Socket[bytes]], service: str, camera: str, stop: threading.Event) -> None:
    push = ctx.socket(zmq.PUSH)
    push.setsockopt(zmq.LINGER, 0)
    push.setsockopt(zmq.SNDHWM, 16)
    push.connect(NOTIFY_ENDPOINT)
    sem = None
    try:
        while not stop.is_set():
            if sem is None:
                try:
                    sem = posix_ipc.Semaphore(naming.semaphore_name(service, camera))
                except posix_ipc.ExistentialError:
                    stop.wait(_WAIT_S)
                    continue
            try:
                sem.acquire(_WAIT_S)  # releases the GIL while blocked
            except posix_ipc.BusyError:
                continue
            except posix_ipc.ExistentialError:
                sem.close()
                sem = None
                continue
            try:
                push.send(camera.encode(), zmq.NOBLOCK)
            except zmq.Again:
                pass  # the loop already has notifications queued; it reads the rings anyway
    finally:
        if sem is not None:
            sem.close()
        push.close()


class FrameWatch:
    """One watcher thread per camera; ``pull`` is the socket to poll."""

    def __init__(self, ctx: zmq.Context[zmq.Socket[bytes]], service: str, cameras: list[str]):
        self.pull = ctx.socket(zmq.PULL)
        self.pull.setsockopt(zmq.LINGER, 0)
        self.pull.bind(NOTIFY_ENDPOINT)
        self._stop = threading.Event()
        self._threads = [
            threading.Thread(target=_watch, args=(ctx, service, cam, self._stop), name=f"watch-{cam}", daemon=True)
            for cam in cameras
        ]
        for t in self._threads:
            t.start()

    def drain(self) -> set[str]:
        """Names of the cameras that stored frames since the last drain."""
        updated = set()
        while True:
            try:
                updated.add(self.pull.recv(zmq.NOBLOCK).decode())
            except zmq.Again:
                return updated

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2 * _WAIT_S + 1)
        self.pull.close()
