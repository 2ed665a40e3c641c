"""The picture of a sync report (``fxis sync-report --plot FILE``): each tuple's gap over the
run, the threshold as a line and dropped slots as red ticks below the axis; beside it, the
gaps' histogram. Drawn with OpenCV, which the project already depends on."""

from __future__ import annotations

import math

import cv2
import numpy as np

from fxis_shm.core.syncstats import Figures, Samples, gaps_ns

WIDTH, HEIGHT = 1100, 420
LEFT, RIGHT, TOP, BOTTOM = 70, 20, 40, 60  # margins of each panel, px
SPLIT = 720  # where the histogram's panel starts
BINS = 30
INK, GRID, POINT, LIMIT, DROP = (20, 20, 20), (225, 225, 225), (180, 90, 20), (40, 40, 200), (0, 0, 230)
FONT = cv2.FONT_HERSHEY_SIMPLEX


def draw(samples: Samples, figures: Figures, threshold_ms: float, title: str) -> np.ndarray:
    """The plot as a BGR image."""
    image = np.full((HEIGHT, WIDTH, 3), 255, dtype=np.uint8)
    gaps_ms = gaps_ns(samples) / 1e6
    seconds = (samples.slots - samples.slots[0]) / 1e9 if len(samples.slots) else np.zeros(0)
    shown = gaps_ms[~np.isnan(gaps_ms)]
    top = nice_ticks(max(threshold_ms * 1.5, float(shown.max()) * 1.1 if len(shown) else 0.0, 1.0))[-1]
    _text(image, title, (LEFT, 24), 0.55)
    _over_time(image, seconds, gaps_ms, top, threshold_ms)
    _histogram(image, shown, top, threshold_ms)
    verdict = "PASS" if figures.passed else "FAIL"
    _text(image, verdict, (WIDTH - RIGHT - 60, 24), 0.6, (0, 140, 0) if figures.passed else DROP)
    return image


def write(path: str, image: np.ndarray) -> None:
    if not cv2.imwrite(path, image):
        raise OSError(0, "OpenCV could not write the plot (a .png path in a folder that exists?)", path)


def _text(image: np.ndarray, text: str, at: tuple[int, int], scale: float = 0.45, color=INK) -> None:
    cv2.putText(image, text, at, FONT, scale, color, 1, cv2.LINE_AA)


def nice_ticks(top: float, most: int = 6) -> list[float]:
    """Evenly spaced round ticks from 0 (a step of 1, 2 or 5 times a power of ten), at most
    ``most`` + 1 of them, the last at or above ``top``."""
    if not top > 0:
        return [0.0, 1.0]
    power = 10.0 ** math.floor(math.log10(top / most))
    step = next(m * power for m in (1, 2, 5, 10) if top / (m * power) <= most)
    count = math.ceil(top / step - 1e-9)
    return [round(k * step, 12) for k in range(count + 1)]


def _label(value: float) -> str:
    return f"{value:g}"


def _axes(image: np.ndarray, x0: int, x1: int, top_ms: float, x_label: str, y_label: str) -> None:
    y0, y1 = TOP, HEIGHT - BOTTOM
    for tick in nice_ticks(top_ms):  # gridlines at round values, labelled
        y = _y(tick, top_ms)
        cv2.line(image, (x0, y), (x1, y), GRID, 1)
        _text(image, _label(tick), (x0 - 50, y + 4), 0.4)
    cv2.rectangle(image, (x0, y0), (x1, y1), INK, 1)
    _text(image, x_label, ((x0 + x1) // 2 - 40, HEIGHT - 15))
    _text(image, y_label, (x0 - 60, y0 - 8), 0.4)


def _y(value_ms: float, top_ms: float) -> int:
    y0, y1 = TOP, HEIGHT - BOTTOM
    return int(round(y1 - (y1 - y0) * min(value_ms, top_ms) / top_ms))


def _over_time(image: np.ndarray, seconds: np.ndarray, gaps_ms: np.ndarray, top: float, threshold: float) -> None:
    x0, x1 = LEFT, SPLIT - 40
    _axes(image, x0, x1, top, "time since the first slot (s)", "gap (ms)")
    span = nice_ticks(float(seconds[-1]) if len(seconds) and seconds[-1] > 0 else 1.0)[-1]
    cv2.line(image, (x0, _y(threshold, top)), (x1, _y(threshold, top)), LIMIT, 1, cv2.LINE_AA)
    _text(image, f"threshold {threshold:g} ms", (x1 - 150, _y(threshold, top) - 6), 0.4, LIMIT)
    for s, gap in zip(seconds.tolist(), gaps_ms.tolist()):
        x = int(round(x0 + (x1 - x0) * s / span))
        if np.isnan(gap):  # dropped: no complete tuple
            cv2.line(image, (x, HEIGHT - BOTTOM + 3), (x, HEIGHT - BOTTOM + 12), DROP, 1)
        else:
            cv2.circle(image, (x, _y(gap, top)), 2, POINT, -1, cv2.LINE_AA)
    for tick in nice_ticks(span):  # the time axis labelled at round seconds, not only its ends
        x = int(round(x0 + (x1 - x0) * tick / span))
        cv2.line(image, (x, HEIGHT - BOTTOM), (x, HEIGHT - BOTTOM + 4), INK, 1)
        _text(image, _label(tick), (x - 8, HEIGHT - 32), 0.4)


def _histogram(image: np.ndarray, gaps_ms: np.ndarray, top: float, threshold: float) -> None:
    x0, x1 = SPLIT + LEFT - 20, WIDTH - RIGHT
    _axes(image, x0, x1, top, "tuples", "gap (ms)")
    if not len(gaps_ms):
        _text(image, "no complete tuple", (x0 + 20, HEIGHT // 2))
        return
    counts, edges = np.histogram(np.minimum(gaps_ms, top), bins=BINS, range=(0.0, top))
    most = max(int(counts.max()), 1)
    for count, low, high in zip(counts.tolist(), edges[:-1].tolist(), edges[1:].tolist()):
        if count:
            width = int(round((x1 - x0) * count / most))
            cv2.rectangle(image, (x0, _y(high, top)), (x0 + width, _y(low, top)), POINT, -1)
    cv2.line(image, (x0, _y(threshold, top)), (x1, _y(threshold, top)), LIMIT, 1, cv2.LINE_AA)
    _text(image, f"max {most}", (x1 - 70, HEIGHT - 32), 0.4)
