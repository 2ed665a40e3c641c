"""The embedded default camera: free-running, deterministic, stamped.

Frame k is due at ``origin + phase + k/fps`` on CLOCK_MONOTONIC, where the
origin is shared by every synthetic camera of a service: two cameras with the
same fps and phase capture together (like hardware-triggered cameras), and a
phase offset is exactly the one configured. Deadlines are absolute, so the
period never drifts. Each image is a pattern that moves with k, with k stamped
into its first and last row (``fxis_shm.stamp.read_stamp`` reads it back).
"""
from __future__ import annotations

import random
import time
from fractions import Fraction

import numpy as np

from fxis_shm.options import Option, choice, number
from fxis_shm.ring import FrameLayout
from fxis_shm.stamp import write_stamp

from .base import Camera, Capture

_SHIFT_PER_FRAME = 4  # pixels the pattern moves per frame, so consecutive frames differ everywhere


class SyntheticCamera(Camera):
    kind = "synthetic"
    OPTIONS = {
        "fps": Option(number(float, 0, 10_000, exclusive_min=True), 20.0, "frames per second"),
        "width": Option(number(int, 16, 16384), 1360, "image width in pixels"),
        "height": Option(number(int, 1, 16384), 1024, "image height in pixels"),
        "pixel_format": Option(choice("mono8", "bgr8"), "mono8", "mono8 or bgr8"),
        "phase_ms": Option(number(float), 0.0, "offset of this camera's frame times, ms"),
        "jitter_ms": Option(number(float, 0), 0.0, "uniform timing noise of the capture time, +/- ms"),
        "drop": Option(number(float, 0, 1), 0.0, "probability that a frame is lost"),
        "seed": Option(number(int, 0), 0, "seed of the jitter and drop noise (0: random)"),
    }

    def __init__(self, name, options, time_origin_ns):
        super().__init__(name, options, time_origin_ns)
        o = self.options
        self._period = Fraction(10**9) / Fraction(o["fps"]).limit_denominator(10**6)
        if o["jitter_ms"] * 1e6 >= self._period / 2:
            raise ValueError(f"jitter_ms={o['jitter_ms']} must be below half the frame period "
                             f"({float(self._period) / 2e6:.3f} ms), or frames would reorder")
        self._phase_ns = round(o["phase_ms"] * 1e6)
        self._jitter_ns = round(o["jitter_ms"] * 1e6)
        self._rng = random.Random(o["seed"] or None)
        self._k = 0

    @property
    def layout(self) -> FrameLayout:
        channels = 3 if self.options["pixel_format"] == "bgr8" else 1
        return FrameLayout(self.options["height"], self.options["width"], channels)

    @property
    def nominal_period_ns(self) -> int:
        return round(self._period)

    def open(self) -> None:
        lay = self.layout
        y, x = np.mgrid[0 : lay.height, 0 : lay.width + 256]
        planes = [(x + 2 * y), (2 * x + y), (x + 3 * y)][: lay.channels]
        pattern = (np.stack(planes, axis=-1) & 255).astype(np.uint8)
        self._pattern = pattern[..., 0] if lay.channels == 1 else pattern
        self._image = np.empty(lay.shape, np.uint8)
        self._k = self._index_at(time.monotonic_ns())

    def _due(self, k: int) -> int:
        return self.time_origin_ns + self._phase_ns + int(k * self._period)

    def _index_at(self, t: int) -> int:
        """The first frame index due at or after t."""
        k = int((t - self.time_origin_ns - self._phase_ns) / self._period)
        while self._due(k) < t:
            k += 1
        return max(k, 0)

    def grab(self, timeout: float) -> Capture | None:
        give_up = time.monotonic_ns() + int(timeout * 1e9)
        while True:
            now = time.monotonic_ns()
            late = self._index_at(now - int(self._period)) - self._k
            if late > 0:  # we fell more than a frame behind: those frames are lost
                self.frames_dropped += late
                self._k += late
            t_capture = self._due(self._k)
            if self._jitter_ns:
                t_capture += self._rng.randint(-self._jitter_ns, self._jitter_ns)
            if t_capture > give_up:
                time.sleep(max(0, give_up - now) / 1e9)
                return None
            if t_capture > now:
                time.sleep((t_capture - now) / 1e9)
            k = self._k
            self._k += 1
            if self.options["drop"] and self._rng.random() < self.options["drop"]:
                self.frames_dropped += 1
                continue
            return Capture(self._render(k), k, t_capture)

    def _render(self, k: int) -> np.ndarray:
        shift = (k * _SHIFT_PER_FRAME) % 256
        np.copyto(self._image, self._pattern[:, shift : shift + self.options["width"]])
        write_stamp(self._image, k)
        return self._image
