"""A scene that compresses like a real camera's, for the video benches (issue 35, item 6).

The synthetic cameras' sliding gradient compresses to almost nothing, so its sizes say nothing
about a real camera's. This one is a published photograph seen by a panning camera with sensor
noise:

- the image: ``grace_hopper.jpg``, the US Navy's public-domain portrait of Grace Hopper (512x600
  RGB JPEG), which matplotlib ships as sample data (``matplotlib.cbook.get_sample_data``; the
  ``bench`` extra installs matplotlib), converted to 8-bit gray (OpenCV's BGR2GRAY weights: the
  cameras are mono8);
- enlarged by ``zoom`` (bicubic, default 1.5: 768x900) and mirror-tiled (``numpy.pad``
  ``symmetric``) into a canvas the crop window never leaves;
- seen through a WIDTHxHEIGHT window (1360x1024) that pans slowly on an ellipse: ``pan_px``
  pixels each way horizontally, two thirds of it vertically, one turn every ``period_s``
  seconds, at whole-pixel offsets (at most about 2 px a frame at 30 fps with the defaults);
- with Gaussian sensor noise of ``sigma`` gray levels (default 2.0), drawn afresh for every
  frame from a seeded generator, rounded and clipped to 0..255.

Frame i is a pure function of (i, the settings, the seed). Not a bench: imported by
bench/video/sizes.py and bench/video/anchor.py.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

IMAGE = "grace_hopper.jpg"


@dataclass(frozen=True)
class Scene:
    width: int = 1360
    height: int = 1024
    fps: float = 30.0
    zoom: float = 1.5
    sigma: float = 2.0
    pan_px: int = 100
    period_s: float = 20.0
    seed: int = 35

    def describe(self) -> str:
        return (
            f"matplotlib's {IMAGE} in gray, x{self.zoom:g} bicubic, mirror-tiled, a {self.width}x{self.height} "
            f"window panning +-{self.pan_px} px (x) and +-{self.pan_px * 2 // 3} px (y) every {self.period_s:g} s, "
            f"Gaussian noise sigma {self.sigma:g} gray levels, seed {self.seed}"
        )

    def frames(self, count: int, noise: bool = True) -> list[np.ndarray]:
        """Frames 0 .. count-1 (each a fresh C-contiguous mono8 array); with ``noise`` False, the
        same frames without sensor noise (the signal a codec should keep)."""
        canvas = self._canvas()
        rng = np.random.default_rng(self.seed)
        out = []
        for i in range(count):
            x, y = self._offset(i)
            view = canvas[y : y + self.height, x : x + self.width]
            if noise and self.sigma > 0:
                noisy = view + rng.standard_normal(view.shape, dtype=np.float32) * np.float32(self.sigma)
                out.append(np.clip(np.rint(noisy), 0, 255).astype(np.uint8))
            else:
                out.append(view.copy())
        return out

    def _offset(self, i: int) -> tuple[int, int]:
        """The window's top-left corner in the canvas for frame ``i``."""
        phase = 2 * math.pi * i / (self.fps * self.period_s)
        return (
            self.pan_px + round(self.pan_px * math.sin(phase)),
            self.pan_px + round(self.pan_px * 2 / 3 * math.sin(2 * phase)),
        )

    def _canvas(self) -> np.ndarray:
        import cv2
        from matplotlib import cbook

        bgr = cv2.imread(str(cbook.get_sample_data(IMAGE, asfileobj=False)), cv2.IMREAD_COLOR)
        if bgr is None:
            raise RuntimeError(f"matplotlib's sample image {IMAGE} could not be read")
        gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
        big = cv2.resize(gray, None, fx=self.zoom, fy=self.zoom, interpolation=cv2.INTER_CUBIC)
        need_h, need_w = self.height + 2 * self.pan_px + 1, self.width + 2 * self.pan_px + 1
        pad_h, pad_w = max(0, need_h - big.shape[0]), max(0, need_w - big.shape[1])
        return np.pad(big, ((0, pad_h), (0, pad_w)), mode="symmetric")


def add_scene_args(p) -> None:
    """The scene's flags (``p``: a parser), with Scene's defaults."""
    d = Scene()
    g = p.add_argument_group("the scene (bench/video/scene.py)")
    g.add_argument("--width", type=int, default=d.width, help="frame width (px, even)")
    g.add_argument("--height", type=int, default=d.height, help="frame height (px, even)")
    g.add_argument("--fps", type=float, default=d.fps, help="frame rate the frames are stamped at")
    g.add_argument("--seconds", type=float, default=10.0, help="seconds of the scene encoded")
    g.add_argument("--sigma", type=float, default=d.sigma, help="sensor noise, gray levels (standard deviation)")
    g.add_argument("--zoom", type=float, default=d.zoom, help="enlargement of the photograph")
    g.add_argument("--pan", type=int, default=d.pan_px, help="pixels the window pans each way (x)")


def scene_from(args) -> Scene:
    return Scene(args.width, args.height, args.fps, args.zoom, args.sigma, args.pan, seed=args.seed)


def frame_count(args) -> int:
    return max(1, round(args.seconds * args.fps))


def parse(p, argv):
    """The parsed flags, the results folder, the scene and its frame count: (args, out, scene,
    count); or the exit status of --help or of bad flags."""
    from bench.shared import common

    parsed = common.parse_args_and_out(p, argv)
    if isinstance(parsed, int):
        return parsed
    args, out = parsed
    if args.width % 2 or args.height % 2:
        return common.usage_error(p, "--width and --height must be even (4:2:0 video)")
    return args, out, scene_from(args), frame_count(args)
