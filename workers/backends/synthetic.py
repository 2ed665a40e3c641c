"""The embedded default camera: free-running, deterministic, stamped.

Frame k is due at ``origin + phase + k/fps`` on CLOCK_MONOTONIC, where the
origin is shared by every synthetic camera of a service: two cameras with the
same fps and phase capture together (like hardware-triggered cameras), and a
phase offset is exactly the one configured. Deadlines are absolute, so the
period never drifts. Each image is a pattern that moves with k, with k stamped
into its first and last row (``fxis_shm.formats.stamp.read_stamp`` reads it back).

Two patterns, both drawn once by ``open`` so that a frame costs one copy:

- ``stripes``: diagonal stripes that move 4 px per frame, so consecutive
  frames differ everywhere;
- ``chessboard``: a black and white board of 9x6 inner corners on a white
  margin, which ``cv2.findChessboardCorners`` finds. It sways slowly
  (1 px per frame, at most ``square/4`` px either side of its rest position).

``exposure_us`` and ``gain`` scale the picture's brightness as a real sensor's would
(x exposure_us / 10 ms x 10^(gain/20), clipped at white; the stamp is written after), and
with ``fps`` they change between two frames (``set_live``). A new fps keeps the frame times on
the shared origin's grid of the new period (cameras set alike still capture together) and
the frame ids counting on.

A worker that falls behind gets the frames it missed, late and with their own capture times,
from a pool of ``buffers`` frames as a real camera's driver keeps them (the Aravis backend
queues as many); frames older than that are lost and counted in ``frames_dropped``.

Its clock and its waits are ``clock``'s (fxis_shm.core.timebase.Clock): the real one in a
service; the virtual-time tests (tests/virtualtime) give it a virtual one and schedule its grabs
themselves (``next_due``).

``shift_px`` moves the picture left by that many pixels. Two cameras with the
same fps and phase capture frames with the same k and see the same sway, so
``left`` with shift_px=0 and ``right`` with shift_px=d form a stereo pair
whose disparity (x in left minus x in right) is exactly d pixels.
"""

from __future__ import annotations

import queue
import random
from fractions import Fraction

import numpy as np

from fxis_shm.core import timebase
from fxis_shm.core.tuning import READ_ONLY, RESTART, describe
from fxis_shm.formats.stamp import write_stamp
from fxis_shm.service.camerakinds import SYNTHETIC_EXPOSURE_US
from fxis_shm.shm.ring import FrameLayout

from .base import Camera, Capture

_SHIFT_PER_FRAME = 4  # pixels the stripes move per frame, so consecutive frames differ everywhere
BOARD_CORNERS = (9, 6)  # inner corners per row and per column (cv2's pattern size)
_MIN_SQUARE_PX = 6  # smaller squares are not found reliably


def board_square_px(width: int, height: int) -> int:
    """Side of a chessboard square: about min(width, height)/12 for a 4:3 image,
    and small enough for a margin either side of the board in any aspect."""
    return min(width // 16, height // 12)


class SyntheticCamera(Camera):
    kind = "synthetic"

    def __init__(self, name, options, time_origin_ns, clock: timebase.Clock = timebase.REAL):
        super().__init__(name, options, time_origin_ns)
        self.clock = clock
        o = self.options
        self._period = self._period_of(o["fps"])
        self._grid0 = 0  # frame k is due at index k - _grid0 of the origin's grid (moved by fps changes)
        self._lut: np.ndarray | None = None  # brightness as a look-up table; None: as drawn
        self._set_brightness()
        self._phase_ns = round(o["phase_ms"] * 1e6)
        self._jitter_ns = round(o["jitter_ms"] * 1e6)
        self._rng = random.Random(o["seed"] or None)
        self._k = 0
        # trigger times, ns. A Queue, not a SimpleQueue: on Python 3.11 SimpleQueue.get(timeout)
        # waits for ever when a signal lands near its deadline (a worker that ignored its SIGTERM)
        self._triggers: queue.Queue[int] = queue.Queue()
        self._latency_ns = round(o["trigger_latency_ms"] * 1e6)  # trigger -> exposure
        if o["pattern"] == "chessboard":
            self._check_board_fits()

    def _period_of(self, fps: float) -> Fraction:
        period = Fraction(10**9) / Fraction(fps).limit_denominator(10**6)
        if self.options["jitter_ms"] * 1e6 >= period / 2:
            raise ValueError(
                f"jitter_ms={self.options['jitter_ms']} must be below half the frame period "
                f"({float(period) / 2e6:.3f} ms), or frames would reorder"
            )
        return period

    def _set_brightness(self) -> None:
        gain = self.options["exposure_us"] / SYNTHETIC_EXPOSURE_US * 10 ** (self.options["gain"] / 20)
        if gain == 1:
            self._lut = None
        else:
            self._lut = np.clip(np.arange(256) * gain + 0.5, 0, 255).astype(np.uint8)

    # ---- settings at run time ----

    def settings(self, extra=()) -> dict[str, dict]:
        o = self.options
        jitter_ns = o["jitter_ms"] * 1e6
        max_fps = 10_000.0 if not jitter_ns else min(10_000.0, float(f"{1e9 / (2 * jitter_ns):.6g}") * 0.999)
        described = {
            "exposure_us": describe(o["exposure_us"], "float", lo=1.0, hi=1_000_000.0, unit="us"),
            "gain": describe(o["gain"], "float", lo=0.0, hi=24.0, unit="dB"),
            "fps": describe(o["fps"], "float", lo=0.01, hi=max_fps),
            "width": describe(o["width"], "int", RESTART, lo=16, hi=16384),
            "height": describe(o["height"], "int", RESTART, lo=1, hi=16384),
            "pixel_format": describe(o["pixel_format"], "enum", RESTART, choices=["mono8", "bgr8"]),
        }
        described["trigger"] = describe(o["trigger"], "enum", RESTART, choices=["free", "software"])
        fixed = {"pattern": "enum", "phase_ms": "float", "shift_px": "int", "jitter_ms": "float"}
        for key, type_ in fixed.items():  # set when the service starts
            described[key] = describe(o[key], type_, access=READ_ONLY)
        return described

    def set_live(self, values) -> None:
        if "fps" in values:
            self._change_period(self._period_of(values["fps"]))
        self.options.update(values)
        self._set_brightness()

    def _change_period(self, period: Fraction) -> None:
        """The next frame is due at the first time of the new period's grid from now on."""
        self._period = period
        if self._k < 0:  # not started: frame numbers start on the grid as at start-up
            return
        self._grid0 = 0
        self._grid0 = self._k - self._index_at(self.clock.now_ns())

    def _check_board_fits(self) -> None:
        w, h, shift = self.options["width"], self.options["height"], self.options["shift_px"]
        square = board_square_px(w, h)
        if square < _MIN_SQUARE_PX:
            raise ValueError(
                f"pattern=chessboard needs at least {16 * _MIN_SQUARE_PX}x{12 * _MIN_SQUARE_PX} pixels, got {w}x{h}"
            )
        room = (w - (BOARD_CORNERS[0] + 1) * square) // 2 - square  # keeps a square of margin
        if abs(shift) + square // 4 > room:
            raise ValueError(
                f"shift_px={shift} moves the chessboard out of a {w}x{h} image; "
                f"|shift_px| must be at most {room - square // 4}"
            )

    @property
    def layout(self) -> FrameLayout:
        channels = 3 if self.options["pixel_format"] == "bgr8" else 1
        return FrameLayout(self.options["height"], self.options["width"], channels)

    @property
    def nominal_period_ns(self) -> int:
        return 0 if self.supports_trigger else round(self._period)

    def trigger(self) -> None:
        self._triggers.put(self.clock.now_ns())

    def open(self) -> None:
        lay = self.layout
        if self.options["pattern"] == "chessboard":
            board = self._draw_board(lay.width, lay.height)
            self._pattern = board if lay.channels == 1 else np.repeat(board[..., None], lay.channels, -1)
        else:
            y, x = np.mgrid[0 : lay.height, 0 : lay.width + 256]
            planes = [(x + 2 * y), (2 * x + y), (x + 3 * y)][: lay.channels]
            pattern = (np.stack(planes, axis=-1) & 255).astype(np.uint8)
            self._pattern = pattern[..., 0] if lay.channels == 1 else pattern
        self._image = np.empty(lay.shape, np.uint8)
        self._k = -1  # set by the first grab: frames due while the worker was still setting up are not drops

    def _draw_board(self, width: int, height: int) -> np.ndarray:
        """A canvas ``2 * sway`` px wider than the image: frame k shows a window of it."""
        square = board_square_px(width, height)
        self._sway = square // 4
        cols, rows = BOARD_CORNERS[0] + 1, BOARD_CORNERS[1] + 1  # squares
        canvas = np.full((height, width + 2 * self._sway), 255, np.uint8)
        x0 = self._sway + (width - cols * square) // 2 - self.options["shift_px"]
        y0 = (height - rows * square) // 2
        for r in range(rows):
            for c in range(r % 2, cols, 2):  # the top-left square is black
                canvas[y0 + r * square : y0 + (r + 1) * square, x0 + c * square : x0 + (c + 1) * square] = 0
        return canvas

    def _window(self, k: int) -> int:
        """Left edge of frame k's window into the pattern."""
        if self.options["pattern"] == "chessboard":
            if not self._sway:
                return 0
            p = k % (4 * self._sway)  # a triangle wave over 0..2*sway, 1 px per frame
            return p if p <= 2 * self._sway else 4 * self._sway - p
        return (k * _SHIFT_PER_FRAME + self.options["shift_px"]) % 256

    def _due(self, k: int) -> int:
        return self.time_origin_ns + self._phase_ns + int((k - self._grid0) * self._period)

    def _index_at(self, t: int) -> int:
        """The first frame index due at or after t."""
        k = int((t - self.time_origin_ns - self._phase_ns) / self._period) + self._grid0
        while self._due(k) < t:
            k += 1
        return max(k, self._grid0)

    def grab(self, timeout: float) -> Capture | None:
        if self.supports_trigger:
            return self._grab_triggered(timeout)
        give_up = self.clock.now_ns() + int(timeout * 1e9)
        self._start()
        while True:
            now = self.clock.now_ns()
            # Frames wait in the driver's buffers, as a real camera's do (the sensor does not wait
            # for us): a worker late by up to `buffers` frames gets them all, late; later than
            # that, the oldest are lost.
            late = self._index_at(now - int(self.options["buffers"] * self._period)) - self._k
            if late > 0:
                self.frames_dropped += late
                self._k += late
            t_capture = self._due(self._k)
            if self._jitter_ns:
                t_capture += self._rng.randint(-self._jitter_ns, self._jitter_ns)
            if t_capture > give_up:
                self.clock.sleep_until(give_up)
                return None
            self.clock.sleep_until(t_capture)
            k = self._k
            self._k += 1
            if self.options["drop"] and self._rng.random() < self.options["drop"]:
                self.frames_dropped += 1
                continue
            return Capture(self._render(k), k, t_capture)

    def _grab_triggered(self, timeout: float) -> Capture | None:
        try:
            t_trigger = self._triggers.get(timeout=timeout)
        except queue.Empty:
            return None
        self._start()
        k = self._k
        self._k += 1
        t_capture = t_trigger + self._latency_ns
        self.clock.sleep_until(t_capture)  # a frame is there only after its exposure
        return Capture(self._render(k), k, t_capture)

    def _start(self) -> None:
        """Frame numbers start with the first grab, at the frame due then."""
        if self._k < 0:
            self._k = self._index_at(self.clock.now_ns())

    def next_due(self) -> int:
        """When the next frame of a free-running camera is due (before its jitter): a scheduler
        that runs the grabs itself calls ``grab`` then (tests/virtualtime)."""
        self._start()
        return self._due(self._k)

    def _render(self, k: int) -> np.ndarray:
        x = self._window(k)
        window = self._pattern[:, x : x + self.options["width"]]
        if self._lut is None:
            np.copyto(self._image, window)
        else:
            np.take(self._lut, window, out=self._image)
        write_stamp(self._image, k)
        return self._image
