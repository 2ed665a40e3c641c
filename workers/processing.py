"""Per-camera processing (the paper's "application-specific image processing
routine" run before a frame is stored).

``process=package.module:function`` names a function ``f(image) -> image | None``:
the image it returns is stored (its shape and type fix the ring's layout), None
skips the frame. ``process_workers=n`` runs it in n processes, for hooks slower
than the frame period (the paper's rule: n workers when (n-1)*period < cost <=
n*period); frames still enter the ring in capture order. A hook that raises is
counted (``hook_errors`` in status) and the worker goes on.
"""

from __future__ import annotations

import collections
import concurrent.futures
import importlib
import logging
import multiprocessing
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

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


def _pool_init(path: str) -> None:
    global _pool_hook
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
            n, mp_context=multiprocessing.get_context("spawn"), initializer=_pool_init, initargs=(path,)
        )
        self._pending: collections.deque = collections.deque()
        # Start every process (and import the hook there) now, not on the first frames.
        warm = [self._pool.submit(_pool_warm) for _ in range(n)]
        concurrent.futures.wait(warm, timeout=start_timeout)
        for future in warm:
            future.result(timeout=0)  # raises if a process could not load the hook

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

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)


def pipeline(options: dict):
    path, n = options.get("process"), options.get("process_workers") or 1
    if not path:
        return Direct()
    hook = load_hook(path)  # fails early, in the worker's start-up, with a clear message
    return Inline(hook) if n == 1 else Pool(path, n)
