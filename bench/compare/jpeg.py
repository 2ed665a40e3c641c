"""Which JPEG library to compress frames with: encode and decode time, size, and what survives.

Contenders (one that is not installed is skipped with a note):
  opencv      cv2.imencode / cv2.imdecode (opencv-python-headless; libjpeg-turbo built into the wheel)
  simplejpeg  simplejpeg.encode_jpeg / decode_jpeg (a wheel with libjpeg-turbo built in)
  turbojpeg   PyTurboJPEG's TurboJPEG, ctypes over the system's libturbojpeg (Debian: libturbojpeg0;
              PyTurboJPEG 2.x wants libjpeg-turbo >= 3.0, Debian 12 and 13 ship 2.1, so PyTurboJPEG<2)
  turbojpeg-fastdct  the same with TurboJPEG's default DCT, the fast one below quality 96 (what
              simplejpeg always does: it shows what the fast DCT buys, in time and in PSNR)
  fxis        fxis_shm.wire.encoding.encode / decode: what the service does (OpenCV, with its checks)

All are asked for OpenCV's JPEG: baseline, standard Huffman tables, 4:2:0 chroma for bgr8, the
accurate integer DCT, fancy upsampling on decode; where a library can make it, time is all that
differs (the "=opencv" column checks the bytes). simplejpeg cannot: below quality 96 it always
takes the fast DCT, so its bytes, size and PSNR differ a little.

Frames (--width x --height, default 1360x1024, each mono8 and bgr8):
  stripes     the synthetic camera's default pattern, its frame id stamped into the first and last row
  chessboard  the synthetic camera's pattern=chessboard, stamped likewise
  natural     a made-up photo-like scene: gradients, smoothed noise at three scales, sharp-edged
              shapes and sensor noise (drawn from --seed)

Each round encodes and decodes every frame at every quality with every contender once, in a fresh
random order, so that load from other processes falls on all contenders alike; --rounds rounds are
measured after --warmup unrecorded ones. Per row: wall time of encode and decode (median and p99,
ms; thread CPU time medians are in the JSON), compressed bytes, raw/compressed ratio, PSNR against
the original, whether the bytes equal OpenCV's, and whether fxis_shm.read_stamp still reads the
frame id from the decoded frame. A second table compares encode + decode at --pick-quality.

Writes jpeg_codecs.json (settings, host, library versions, every sample) into --out.
Exit status: 0; 1 if a contender gave back a frame of the wrong size; 2 on bad flags.
"""

from __future__ import annotations

import argparse
import os
import random
import sys
import time

import numpy as np

if not __package__:  # run as a script (python bench/compare/jpeg.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.compare.encoders import CONTENDERS, Contender, load_contenders
from bench.shared import common

IMAGES = ("stripes", "chessboard", "natural")
FORMATS = ("mono8", "bgr8")
STAMPED = ("stripes", "chessboard")


# ---- frames ----------------------------------------------------------------------------------


def synthetic_frame(pattern: str, fmt: str, width: int, height: int) -> tuple[np.ndarray, int]:
    """One frame of the synthetic camera, and the frame id stamped into it."""
    from fxis_shm.workers.backends.synthetic import SyntheticCamera

    options = {"width": width, "height": height, "pixel_format": fmt, "pattern": pattern, "trigger": "software"}
    # an origin 1000 s ago: the frame id is a large number, not 0
    camera = SyntheticCamera("bench", options, time.monotonic_ns() - 1000 * 10**9)
    camera.open()
    try:
        camera.trigger()
        capture = camera.grab(timeout=5.0)
    finally:
        camera.close()
    if capture is None:
        raise RuntimeError("the synthetic camera gave no frame on a software trigger")
    return capture.image.copy(), capture.frame_id


def natural_frame(fmt: str, width: int, height: int, seed: int) -> np.ndarray:
    """A photo-like scene: what a camera looking at a room might give, not a test pattern."""
    import cv2

    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    planes = []
    for c in range(3):
        plane = 70 + 60 * x / width + (40 - 20 * c) * y / height  # light falling off, per colour
        for sigma, amplitude in ((60, 45), (12, 20), (3, 8)):  # shading, texture, fine texture
            noise = cv2.GaussianBlur(rng.standard_normal((height, width)).astype(np.float32), (0, 0), sigma)
            plane += amplitude * noise / noise.std()
        planes.append(plane)
    scene = np.ascontiguousarray(np.stack(planes, axis=-1))
    for _ in range(16):  # objects with sharp edges
        colour = tuple(float(v) for v in rng.uniform(0, 255, 3))
        cx, cy = int(rng.integers(0, width)), int(rng.integers(0, height))
        r = int(rng.integers(1 + height // 40, 2 + height // 6))
        if rng.random() < 0.5:
            cv2.circle(scene, (cx, cy), r, colour, -1, cv2.LINE_AA)
        else:
            cv2.rectangle(scene, (cx - r, cy - r // 2), (cx + r, cy + r // 2), colour, -1)
    if fmt == "mono8":
        scene = cv2.cvtColor(scene, cv2.COLOR_BGR2GRAY)
    scene += rng.normal(0.0, 2.0, scene.shape).astype(np.float32)  # sensor noise
    return np.clip(scene, 0, 255).astype(np.uint8)


def frames(images: list[str], formats: list[str], width: int, height: int, seed: int) -> dict:
    """(image, format) -> (frame, stamped frame id or None)."""
    out = {}
    for image in images:
        for fmt in formats:
            if image in STAMPED:
                out[image, fmt] = synthetic_frame(image, fmt, width, height)
            else:
                out[image, fmt] = natural_frame(fmt, width, height, seed), None
    return out


# ---- measuring -------------------------------------------------------------------------------


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def round_trip(contender: Contender, frame: np.ndarray, quality: int) -> dict:
    """One encode and one decode: wall and thread CPU ns of each, the bytes and the frame back."""
    w0, c0 = time.perf_counter_ns(), time.thread_time_ns()
    data = contender.encode(frame, quality)
    w1, c1 = time.perf_counter_ns(), time.thread_time_ns()
    back = contender.decode(data, frame)
    w2, c2 = time.perf_counter_ns(), time.thread_time_ns()
    return {
        "enc_ns": w1 - w0,
        "dec_ns": w2 - w1,
        "enc_cpu_ns": c1 - c0,
        "dec_cpu_ns": c2 - c1,
        "data": data,
        "back": back,
    }


def describe(
    contender: Contender, frame: np.ndarray, frame_id: int | None, trip: dict, reference: bytes | None
) -> dict:
    """What one round trip shows beyond its time: size, fidelity, shape, stamp."""
    back = trip["back"]
    fits = back is not None and back.size == frame.size and back.dtype == frame.dtype
    restored = back.reshape(frame.shape) if fits else None
    return {
        "bytes": len(trip["data"]),
        "ratio": frame.nbytes / len(trip["data"]),
        "decoded_shape": None if back is None else list(back.shape),
        "same_shape": back is not None and back.shape == frame.shape,
        "error": None if fits else f"decoded to {None if back is None else back.shape}, not {frame.shape}",
        "psnr_db": psnr(frame, restored) if fits else None,
        "same_bytes_as_opencv": None if reference is None else trip["data"] == reference,
        "stamp_ok": None if frame_id is None or not fits else common.read_stamp(restored) == frame_id,
    }


def run(args, contenders: list[Contender], source: dict) -> dict:
    """Per (image, format, quality, contender): the samples and what the round trip showed."""
    cases = [(image, fmt, q) for (image, fmt) in source for q in args.qualities]
    items = [(case, c) for case in cases for c in contenders]
    rng = random.Random(args.seed)
    results = {
        (*case, c.name): {"samples": {k: [] for k in ("enc_ns", "dec_ns", "enc_cpu_ns", "dec_cpu_ns")}}
        for case, c in items
    }
    reference = {
        (image, fmt, q): c.encode(source[image, fmt][0], q) for (image, fmt, q), c in items if c.name == "opencv"
    }
    for (image, fmt, q), c in items:  # a first, unrecorded trip: what it shows, once
        frame, frame_id = source[image, fmt]
        trip = round_trip(c, frame, q)
        theirs = reference.get((image, fmt, q)) if c.name != "opencv" else None
        results[image, fmt, q, c.name].update(describe(c, frame, frame_id, trip, theirs))
    for _ in range(args.warmup):
        for (image, fmt, q), c in items:
            round_trip(c, source[image, fmt][0], q)
    with common.progress(args.rounds * len(items), "jpeg_codecs") as bar:
        for _ in range(args.rounds):
            rng.shuffle(items)
            for (image, fmt, q), c in items:
                trip = round_trip(c, source[image, fmt][0], q)
                samples = results[image, fmt, q, c.name]["samples"]
                for key in samples:
                    samples[key].append(trip[key])
                bar.update(1)
    for r in results.values():
        r["summary_ms"] = {
            k.replace("_ns", ""): common.summary([common.ms(v) for v in vals]) for k, vals in r["samples"].items()
        }
    return results


# ---- report ----------------------------------------------------------------------------------


def yes_no(value) -> str:
    return "-" if value is None else ("yes" if value else "NO")


def full_table(results: dict) -> str:
    rows = []
    for (image, fmt, q, name), r in results.items():
        s = r["summary_ms"]
        rows.append(
            [
                f"{image} {fmt} q{q} {name}",
                s["enc"]["median"],
                s["enc"]["p99"],
                s["dec"]["median"],
                s["dec"]["p99"],
                r["bytes"],
                r["ratio"],
                r["psnr_db"],
                yes_no(r["same_bytes_as_opencv"]),
                "x".join(map(str, r["decoded_shape"] or [])),
                yes_no(r["stamp_ok"]),
            ]
        )
    rows.sort(key=lambda row: row[0])
    return common.table(
        [
            "frame, quality, contender",
            "enc med",
            "enc p99",
            "dec med",
            "dec p99",
            "bytes",
            "raw/jpeg",
            "PSNR dB",
            "=opencv",
            "decoded",
            "stamp",
        ],
        rows,
        title="times in ms (wall); '=opencv': the same bytes as OpenCV's; "
        "'stamp': read_stamp gives the frame id after the round trip",
        separators=(1, 5),
    )


def pick_table(results: dict, quality: int) -> tuple[str, dict]:
    """encode + decode medians at ``quality`` (wall and thread CPU time), and each contender's
    speed-up over OpenCV in both, with their geometric means over the frames."""

    def medians(r):
        s = r["summary_ms"]
        return s["enc"]["median"] + s["dec"]["median"], s["enc_cpu"]["median"] + s["dec_cpu"]["median"]

    rows, speedups = [], {}
    for (image, fmt, q, name), r in sorted(results.items()):
        if q != quality:
            continue
        wall, cpu = medians(r)
        base = results.get((image, fmt, q, "opencv"))
        fast_wall = fast_cpu = size = None
        if base is not None:
            base_wall, base_cpu = medians(base)
            fast_wall, fast_cpu, size = base_wall / wall, base_cpu / cpu, r["bytes"] / base["bytes"]
            speedups.setdefault(name, []).append((fast_wall, fast_cpu))
        rows.append([f"{image} {fmt} {name}", wall, cpu, fast_wall, fast_cpu, size, r["psnr_db"]])
    geo = {
        name: {
            "wall": float(np.exp(np.mean(np.log([w for w, _ in v])))),
            "cpu": float(np.exp(np.mean(np.log([c for _, c in v])))),
        }
        for name, v in speedups.items()
    }
    text = common.table(
        ["frame, contender", "enc+dec ms", "cpu ms", "x speed", "x speed cpu", "x size", "PSNR dB"],
        rows,
        title=f"at quality {quality}: encode + decode, medians of wall and thread CPU "
        f"time; 'x': relative to OpenCV (speed > 1 is faster)",
        digits=3,
    )
    text += "\ngeometric mean of the speed-ups over OpenCV (wall, cpu): " + ", ".join(
        f"{name} {g['wall']:.2f}x {g['cpu']:.2f}x" for name, g in geo.items()
    )
    return text, geo


def quality_list(text: str) -> list[int]:
    values = common.int_list(text)
    if min(values) < 1 or max(values) > 100:
        raise argparse.ArgumentTypeError(f"JPEG qualities are 1 to 100, got {text!r}")
    return values


def parser() -> argparse.ArgumentParser:
    p = common.parser_for(__file__, __doc__)
    p.add_argument(
        "-n",
        "--rounds",
        type=common.positive_int,
        default=50,
        help="measured rounds (each one encode and decode of every row)",
    )
    p.add_argument("--warmup", type=int, default=2, help="unrecorded rounds first")
    p.add_argument(
        "--contenders",
        type=common.name_list(CONTENDERS),
        default=",".join(CONTENDERS),
        metavar="LIST",
        help="comma-separated: " + ",".join(CONTENDERS),
    )
    p.add_argument(
        "--images",
        type=common.name_list(IMAGES),
        default=",".join(IMAGES),
        metavar="LIST",
        help="comma-separated: " + ",".join(IMAGES),
    )
    p.add_argument("--formats", type=common.name_list(FORMATS), default=",".join(FORMATS), metavar="LIST")
    p.add_argument("--qualities", type=quality_list, default="75,90,95", metavar="LIST")
    p.add_argument(
        "--pick-quality", type=int, default=90, help="the quality the second table compares at (one of --qualities)"
    )
    common.add_frame_size_args(p, 1360, 1024)
    p.add_argument("--out", default=common.DEFAULT_OUT, metavar="DIR", help="folder for the JSON file")
    p.add_argument(
        "--seed",
        type=int,
        default=None,
        help="seed of the natural frame and of the order (default: random; saved in the JSON)",
    )
    return p


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = common.parse_args(p, argv)
    if isinstance(args, int):
        return args
    if args.pick_quality not in args.qualities:
        return common.usage_error(p, f"--pick-quality {args.pick_quality} is not one of --qualities")
    if args.width < 16:
        return common.usage_error(p, "--width must be at least 16 (a row holds the 16-byte stamp)")
    contenders = load_contenders(args.contenders)
    if not contenders:
        return common.usage_error(p, "none of the --contenders is installed")
    started = time.time()
    host = common.host_info()
    try:
        source = frames(args.images, args.formats, args.width, args.height, args.seed)
    except ValueError as exc:  # e.g. a chessboard that does not fit
        return common.usage_error(p, str(exc))
    results = run(args, contenders, source)

    print(common.code_line(host["code"]))
    print(
        f"jpeg_codecs: {args.width}x{args.height}, {args.rounds} rounds interleaved in random order "
        f"(seed {args.seed}), load average before: {os.getloadavg()[0]:.2f}"
    )
    for c in contenders:
        print(f"  {c.name}: {c.version}; mono8 input: {c.mono_input}")
    print(full_table(results))
    pick, geo = pick_table(results, args.pick_quality)
    print(pick)
    failed = [(key, r["error"]) for key, r in results.items() if r["error"]]
    for key, error in failed:
        print(f"  failed: {' '.join(map(str, key))}: {error}")

    json_path = os.path.join(common.ensure_dir(args.out), "jpeg_codecs.json")
    common.write_json(
        json_path,
        {
            **common.run_record("jpeg_codecs", started, argv, args),
            "host": host,
            "load_average_after": os.getloadavg(),
            "contenders": {c.name: {"version": c.version, "mono_input": c.mono_input} for c in contenders},
            "speedup_over_opencv_geomean": geo,
            "rows": [
                {"image": image, "format": fmt, "quality": q, "contender": name, **{k: v for k, v in r.items()}}
                for (image, fmt, q, name), r in results.items()
            ],
        },
    )
    print(f"wrote {json_path}")
    return common.EXIT_FAILED if failed else common.EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
