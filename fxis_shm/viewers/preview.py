"""What the live dashboard shows, computed without I/O: the viewer's parameters checked,
frames scaled down and JPEG-encoded once (a small cache shared by every viewer), the
measured frame rate, and the short histories its plots draw.

Pure: arrays and numbers in, bytes and numbers out. fxis_shm.viewers.dashboard does the I/O.
"""

from __future__ import annotations

import math
from collections import OrderedDict, deque
from collections.abc import Callable, Hashable

import cv2
import numpy as np

from fxis_shm.errors import InvalidArgument
from fxis_shm.wire import encoding

DEFAULT_WIDTH = 640  # a preview no wider than this unless the viewer asks
MAX_WIDTH = 4096
DEFAULT_FPS = 5.0
MAX_FPS = 60.0
PREVIEW_QUALITY = 80  # JPEG quality of previews: small files, still judged sharp by eye
CACHE_ENTRIES = 64  # a few frames of every camera at a few widths


def parse_width(text: str | None, default: int = DEFAULT_WIDTH) -> int:
    """``?width=`` as given: a whole number of pixels from 1 to MAX_WIDTH."""
    if text is None or text == "":
        return default
    try:
        width = int(text)
    except ValueError:
        raise InvalidArgument(f"width must be a whole number of pixels, got {text!r}") from None
    if not 1 <= width <= MAX_WIDTH:
        raise InvalidArgument(f"width must be from 1 to {MAX_WIDTH} pixels, got {width}")
    return width


def parse_fps(text: str | None, default: float = DEFAULT_FPS) -> float:
    """``?fps=`` as given: frames per second, > 0 and at most MAX_FPS."""
    if text is None or text == "":
        return default
    try:
        fps = float(text)
    except ValueError:
        raise InvalidArgument(f"fps must be a number of frames per second, got {text!r}") from None
    if not (0 < fps <= MAX_FPS):  # also refuses nan
        raise InvalidArgument(f"fps must be > 0 and at most {MAX_FPS:g}, got {text}")
    return fps


def displayable(image: np.ndarray) -> np.ndarray:
    """The frame as 8-bit mono or BGR, what JPEG takes: 16-bit keeps its high byte,
    a fourth channel (alpha) is dropped."""
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    elif image.dtype != np.uint8:
        image = cv2.normalize(image, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    if image.ndim == 3 and image.shape[2] == 4:
        image = image[:, :, :3]
    elif image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    return image


def scaled(image: np.ndarray, width: int) -> np.ndarray:
    """The frame no wider than ``width`` (never enlarged), aspect ratio kept."""
    h, w = image.shape[:2]
    if w <= width:
        return image
    height = max(1, round(h * width / w))
    return cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)


def preview_jpeg(image: np.ndarray, width: int, quality: int = PREVIEW_QUALITY) -> bytes:
    """The frame as the page shows it: displayable, scaled down, JPEG (the project's codec)."""
    return encoding.encode(scaled(displayable(image), width), encoding.JPEG, quality)


class EncodedCache:
    """The last few encoded previews, keyed by (camera, generation, frame id, width):
    however many viewers look, each frame shown is encoded once. Least recently used out."""

    def __init__(self, entries: int = CACHE_ENTRIES):
        self.entries = entries
        self._items: OrderedDict[Hashable, bytes] = OrderedDict()
        self.encoded = 0  # how many encodings the cache did not spare (for tests and benches)

    def get(self, key: Hashable, make: Callable[[], bytes]) -> bytes:
        data = self._items.get(key)
        if data is None:
            data = make()
            self.encoded += 1
            self._items[key] = data
            while len(self._items) > self.entries:
                self._items.popitem(last=False)
        else:
            self._items.move_to_end(key)
        return data

    def discard(self, key: Hashable) -> None:
        self._items.pop(key, None)


def preview_key(camera: str, generation: int, frame_id: int, width: int) -> tuple:
    return camera, generation, frame_id, width


class RateMeter:
    """Frames per second measured from a counter sampled now and then (``frames_stored``
    of the status): the rate over the samples of the last ``window_s`` seconds."""

    def __init__(self, window_s: float = 5.0):
        self.window_ns = int(window_s * 1e9)
        self._samples: deque[tuple[int, int]] = deque()

    def add(self, t_ns: int, count: int) -> float | None:
        if self._samples and count < self._samples[-1][1]:
            self._samples.clear()  # the counter started again (a new ring generation)
        self._samples.append((t_ns, count))
        while len(self._samples) > 2 and t_ns - self._samples[0][0] > self.window_ns:
            self._samples.popleft()
        (t0, c0), (t1, c1) = self._samples[0], self._samples[-1]
        return round((c1 - c0) * 1e9 / (t1 - t0), 2) if t1 > t0 else None


def frame_intervals_ms(rows: list[list[int]], columns: list[str], last: int) -> list[float]:
    """The intervals between consecutive stored frames (ms) of the newest ``last`` + 1 frames
    of a ``frames`` op reply (rows oldest first). Frames the camera dropped make the interval
    across them long: a spike, as a stutter is. Only a restart (another generation, its ids
    counted afresh) breaks the series."""
    i_t = columns.index("t_capture")
    i_gen = columns.index("generation") if "generation" in columns else None
    rows = rows[-(last + 1) :]
    return [round((b[i_t] - a[i_t]) / 1e6, 3) for a, b in zip(rows, rows[1:]) if i_gen is None or a[i_gen] == b[i_gen]]


class SkewHistory:
    """The skew (ms) of the last synchronized tuples, with the time each was taken (seconds of a
    monotonic count the caller keeps)."""

    def __init__(self, length: int = 120):
        self._points: deque[tuple[float, float]] = deque(maxlen=length)

    def add(self, t_s: float, skew_ns: int) -> None:
        if math.isfinite(t_s):
            self._points.append((round(t_s, 3), round(skew_ns / 1e6, 3)))

    def points(self, now_s: float) -> list[tuple[float, float]]:
        """(seconds relative to ``now_s``, negative: ago; skew ms), oldest first: what the page
        draws against "seconds ago", whenever it looks."""
        return [(round(t - now_s, 3), skew) for t, skew in self._points]
