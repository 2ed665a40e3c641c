"""Per-camera processing (the paper's "application-specific image processing
routine" run before a frame is stored).

``process=package.module:function`` names a function ``f(image) -> image | None``:
the image it returns is stored (its shape and type fix the ring's layout), None
skips the frame. ``process_workers=n`` runs it in n processes, for hooks slower
than the frame period (the paper's rule: n workers when (n-1)*period < cost <=
n*period); frames still enter the ring in capture order. A hook that raises is
counted (``hook_errors`` in status) and the worker goes on.

The processes of a pool end with the worker however it ends: closed (SIGTERM, a stop) they get
a bounded time to finish their frame and are then killed; if the worker dies (kill -9) the
kernel kills them (a parent-death signal each sets as it starts), and multiprocessing's resource
tracker, which they and the worker keep open, then sees its pipe close and ends too.
"""

from __future__ import annotations

import collections
import concurrent.futures
import importlib
import logging
import multiprocessing
import os
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fxis_shm.service.tether import die_with_parent

log = logging.getLogger("camera")


def load_hook(path: str) -> Callable[[np.ndarray], np.ndarray | None]:
    module, _, function = path.partition(":")
    try:
        hook = getattr(importlib.import_module(module), function)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"process={path}: cannot load it: {exc}") from None
    if not callable(hook):
        raise ValueError(f"process={path}: {function} is not callable")
    return hook


@dataclass
class Processed:
    """A frame ready to be stored (``image`` None: skip it; ``error``: the hook raised)."""

    image: np.ndarray | None
    frame_id: int
    t_capture: int
    t_available: int
    error: str | None = None


def run_hook(hook, image: np.ndarray) -> tuple[np.ndarray | None, str | None]:
    try:
        out = hook(image)
    except Exception as exc:  # counted and reported; the worker goes on
        return None, f"{type(exc).__name__}: {exc}"
    if out is not None and not isinstance(out, np.ndarray):
        return None, f"returned {type(out).__name__}, not a NumPy array or None"
    return out, None


class Direct:
    """No hook: frames are stored as captured."""

    in_flight = 0
    hook = None

    def submit(self, capture, t_available: int) -> bool:
        self._next = Processed(capture.image, capture.frame_id, capture.t_capture, t_available)
        return True

    def ready(self) -> list[Processed]:
        done, self._next = [getattr(self, "_next", None)], None
        return [d for d in done if d is not None]

    def close(self) -> None:
        pass


class Inline(Direct):
    """The hook runs in the camera worker itself."""

    def __init__(self, hook):
        self.hook = hook

    def submit(self, capture, t_available: int) -> bool:
        image, error = run_hook(self.hook, capture.image)
        self._next = Processed(image, capture.frame_id, capture.t_capture, t_available, error)
        return True


_pool_hook = None
CLOSE_TIMEOUT_S = 2.0  # a closing pool's processes finish the frame they hold within this, or are killed


def _pool_init(path: str, worker_pid: int) -> None:
    global _pool_hook
    # killed by the kernel when the worker that started it dies, even by kill -9 (the pool's own
    # pipes never tell it: it holds their ends itself); a worker gone already is not waited for
    die_with_parent(signal.SIGKILL)
    if os.getppid() != worker_pid:
        os._exit(0)
    _pool_hook = load_hook(path)


def _pool_warm() -> None:
    time.sleep(0.05)  # long enough that the n warm-up tasks land on n processes


def _pool_run(image: np.ndarray):
    return run_hook(_pool_hook, image)


class Pool:
    """The hook runs in ``n`` processes; results come back in submission order.
    At most ``n`` frames are in flight: a frame arriving while all are busy is
    dropped (counted), so a hook that is too slow never grows a queue."""

    def __init__(self, path: str, n: int, start_timeout: float = 60.0):
        self.n = n
        self.hook = load_hook(path)  # also here, for the first frame, which fixes the layout
        self._pool = concurrent.futures.ProcessPoolExecutor(
            n, mp_context=multiprocessing.get_context("spawn"), initializer=_pool_init, initargs=(path, os.getpid())
        )
        self._pending: collections.deque = collections.deque()
        # Start every process (and import the hook there) now, not on the first frames.
        warm = [self._pool.submit(_pool_warm) for _ in range(n)]
        try:
            concurrent.futures.wait(warm, timeout=start_timeout)
            for future in warm:
                future.result(timeout=0)  # raises if a process could not load the hook
        except BaseException:
            self.close()
            raise

    @property
    def in_flight(self) -> int:
        return len(self._pending)

    def submit(self, capture, t_available: int) -> bool:
        if len(self._pending) >= self.n:
            return False
        future = self._pool.submit(_pool_run, np.array(capture.image))  # the camera reuses its buffer
        self._pending.append((future, capture.frame_id, capture.t_capture, t_available))
        return True

    def ready(self) -> list[Processed]:
        done = []
        while self._pending and self._pending[0][0].done():
            future, frame_id, t_capture, t_available = self._pending.popleft()
            try:
                image, error = future.result()
            except Exception as exc:  # the process running the hook died
                image, error = None, f"processing process failed: {exc!r}"
            done.append(Processed(image, frame_id, t_capture, t_available, error))
        return done

    def close(self, timeout: float = CLOSE_TIMEOUT_S) -> None:
        """Stop the processes: each finishes its frame within ``timeout`` or is killed. Waited
        for here, not at interpreter exit: a forked worker leaves by ``os._exit``, which skips
        the executor's exit hook."""
        processes = list((self._pool._processes or {}).values())  # the executor forgets them on shutdown
        self._pool.shutdown(wait=False, cancel_futures=True)
        deadline = time.monotonic() + timeout
        for process in processes:
            process.join(max(0.0, deadline - time.monotonic()))
        for process in processes:
            if process.is_alive():
                log.warning("processing process %d did not stop within %.0f s; killing it", process.pid, timeout)
                process.kill()
                process.join(timeout)


def pipeline(options: dict):
    path, n = options.get("process"), options.get("process_workers") or 1
    if not path:
        return Direct()
    hook = load_hook(path)  # fails early, in the worker's start-up, with a clear message
    return Inline(hook) if n == 1 else Pool(path, n)
