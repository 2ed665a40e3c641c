"""Size per hour and quality of each recording encoding, on a scene that compresses like a real
camera's (bench/video/scene.py: a published photograph, panning, with sensor noise).

Makes --seconds of the scene at --fps (1360x1024 mono8 by default), then per encoding:
  raw    the frames as they are (what `fxis record` writes by default);
  jpeg   each frame through the project's JPEG codec at q90 (fxis_shm/wire/encoding.py, what
         `fxis record --encoding jpeg` writes);
  h264, h265, av1   every frame through the encoder `fxis record --codec C` chooses and configures
         with its defaults (fxis_shm.formats.videotracks.VideoPlan, software encoder: CRF 23 /
         28 / 35, presets veryfast / ultrafast / 11, a keyframe every 2 s), frames stamped 1/fps
         apart, then decoded back with FFmpeg's decoders.
Measures the bytes of each frame, extrapolates to --cameras cameras for an hour
(bytes a frame x fps x 3600 x cameras), and the quality of what a reader gets back against the
raw frames: PSNR (dB, of each frame; mean and min) and SSIM (Wang et al.'s, 11x11 Gaussian
window sigma 1.5, on every --ssim-every-th frame). The raw frames hold the sensor noise, which
a codec mostly smooths away (a perfect denoiser would score 20 log10(255 / sigma), 42 dB at
sigma 2): "PSNR signal" is the mean PSNR against the same frames without noise, what the codec
kept of the scene itself. Also the encoding's CPU time a frame in this
process (user + system, every thread; bench/video/anchor.py compares it with the ffmpeg CLI).

Prints the table and writes video_sizes.json into --out. Exit status 0; 2 on bad flags.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

if not __package__:  # run as a script (python bench/video/sizes.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common
from bench.video import product
from bench.video.scene import add_scene_args, parse
from fxis_shm.wire import encoding

ENCODINGS = ("raw", "jpeg", "h264", "h265", "av1")
JPEG_QUALITY = encoding.DEFAULT_JPEG_QUALITY


def parser():
    p = common.parser_for(__file__, __doc__)
    p.add_argument(
        "--encodings", type=common.name_list(ENCODINGS), default=list(ENCODINGS), help="comma-separated, of these"
    )
    p.add_argument("--cameras", type=common.positive_int, default=4, help="cameras the hourly size is given for")
    p.add_argument("--ssim-every", type=common.positive_int, default=10, help="SSIM on every Nth frame")
    add_scene_args(p)
    common.add_output_args(p, seed_help="seed of the scene's sensor noise")
    return p


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float32) - b.astype(np.float32)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def ssim(a: np.ndarray, b: np.ndarray) -> float:
    """Mean SSIM of two 8-bit gray images (Wang et al. 2004: 11x11 Gaussian, sigma 1.5)."""
    import cv2

    x, y = a.astype(np.float32), b.astype(np.float32)
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2

    def blur(z):
        return cv2.GaussianBlur(z, (11, 11), 1.5)

    mx, my = blur(x), blur(y)
    sxx, syy, sxy = blur(x * x) - mx * mx, blur(y * y) - my * my, blur(x * y) - mx * my
    num = (2 * mx * my + c1) * (2 * sxy + c2)
    return float(np.mean(num / ((mx * mx + my * my + c1) * (sxx + syy + c2))))


def measure(name: str, frames: list[np.ndarray], signal: list[np.ndarray], fps: float, ssim_every: int) -> dict:
    """Bytes a frame, CPU a frame and quality of one encoding."""
    if name == "raw":
        sizes, decoded, cpu, what = [f.nbytes for f in frames], frames, 0.0, "mono8 Image"
    elif name == "jpeg":
        cpu0 = product.cpu_seconds()
        blobs = [encoding.encode(f, encoding.JPEG, JPEG_QUALITY) for f in frames]
        cpu = product.cpu_seconds() - cpu0
        sizes, what = [len(b) for b in blobs], f"q{JPEG_QUALITY}, fxis_shm/wire/encoding.py"
        decoded = [encoding.decode(b, encoding.JPEG, f.shape, "uint8") for b, f in zip(blobs, frames)]
    else:
        done = product.encode(name, frames, fps)
        plan = done.plan
        sizes, cpu = [len(p) for p in done.packets], done.cpu_s
        what = f"{plan.choice.encoder} CRF {plan.crf} {plan.preset}, GOP {plan.gop_s:g} s"
        decoded = product.decode(name, done.packets)
    if len(decoded) != len(frames):
        raise RuntimeError(f"{name}: {len(frames)} frames, {len(decoded)} decoded")
    exact = name == "raw"  # (its PSNR is infinite, its SSIM 1)
    psnrs = [] if exact else [psnr(f, d) for f, d in zip(frames, decoded)]
    signal_psnrs = [psnr(f, d) for f, d in zip(signal, decoded)]
    ssims = [] if exact else [ssim(f, d) for f, d in zip(frames[::ssim_every], decoded[::ssim_every])]
    return {
        "what": what,
        "bytes_per_frame": float(np.mean(sizes)),
        "bytes": common.summary(sizes),
        "cpu_ms_per_frame": cpu / len(frames) * 1e3,
        "psnr_db": common.summary(psnrs),
        "signal_psnr_db": common.summary(signal_psnrs),
        "ssim": common.summary(ssims),
    }


def main(argv: list[str] | None = None) -> int:
    parsed = parse(parser(), argv)
    if isinstance(parsed, int):
        return parsed
    args, out, scene, n = parsed
    print(f"scene: {scene.describe()}; {n} frames ({args.seconds:g} s at {args.fps:g} fps)", file=sys.stderr)
    frames, signal = scene.frames(n), scene.frames(n, noise=False)
    load = os.getloadavg()
    results = {}
    for name in args.encodings:
        t0 = time.monotonic()
        print(f"{name} ...", file=sys.stderr, flush=True)
        results[name] = measure(name, frames, signal, args.fps, args.ssim_every)
        print(f"{name}: done in {time.monotonic() - t0:.1f} s", file=sys.stderr, flush=True)
    per_hour = args.fps * 3600 * args.cameras
    raw = frames[0].nbytes
    rows = []
    for name, r in results.items():
        b = r["bytes_per_frame"]
        ssim_mean = r["ssim"]["mean"]
        rows.append(
            [
                name,
                r["what"],
                f"{b / 1e3:,.1f}",
                f"{raw / b:,.0f}",
                f"{b * args.fps * args.cameras / 1e6:,.2f}",
                f"{b * per_hour / 1e9:,.1f}",
                "exact" if name == "raw" else f"{r['psnr_db']['mean']:.2f} / {r['psnr_db']['min']:.2f}",
                "exact" if name == "raw" else f"{ssim_mean:.4f}",
                f"{r['signal_psnr_db']['mean']:.2f}",
                f"{r['cpu_ms_per_frame']:.1f}" if name != "raw" else "-",
            ]
        )
    title = (
        f"{args.cameras} cameras of {args.width}x{args.height} mono8 at {args.fps:g} fps, "
        f"from {n} frames of the scene; "
        f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} ({os.cpu_count()} CPUs)"
    )
    header = [
        "encoding",
        "settings",
        "kB/frame",
        "x smaller",
        "MB/s",
        "GB/hour",
        "PSNR dB mean/min",
        "SSIM",
        "PSNR signal",
        "CPU ms/frame",
    ]
    kept = {"settings": vars(args), "scene": scene.describe(), "load_average": load, "results": results}
    print(common.table(header, rows, title=title))
    print(f"scene: {kept['scene']}")
    print(common.code_line(common.code_version()))
    common.write_json(os.path.join(out, "video_sizes.json"), {**kept, "host": common.host_info()})
    return common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
