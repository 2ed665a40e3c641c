"""The JPEG libraries bench/compare/jpeg.py measures, each behind one small interface: OpenCV's
(what fxis_shm.wire.encoding uses), simplejpeg, PyTurboJPEG (accurate and fast DCT) and the project's
own codec module. Each is asked for OpenCV's JPEG (4:2:0 chroma for bgr8, accurate DCT) where it
can make it, so that time is the only difference. Not a public module."""

from __future__ import annotations

import ctypes.util
import sys
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bench.shared import common

CONTENDERS = ("opencv", "simplejpeg", "turbojpeg", "turbojpeg-fastdct", "fxis")


@dataclass
class Contender:
    name: str
    version: str
    mono_input: str  # what the library takes for a mono8 frame
    encode: Callable[[np.ndarray, int], bytes]
    decode: Callable[[bytes, np.ndarray], np.ndarray]  # (data, the original frame) -> the library's output


def _jpeg_line_of_opencv(cv2) -> str:
    lines = [
        line.split(":", 1)[1].strip()
        for line in cv2.getBuildInformation().splitlines()
        if line.strip().startswith("JPEG:")
    ]
    return lines[0] if lines else "?"


def opencv() -> Contender:
    import cv2

    def encode(image, quality):
        ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
        if not ok:
            raise RuntimeError(f"cv2.imencode refused a {image.shape} frame")
        return buf.tobytes()

    def decode(data, _):
        return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)

    return Contender("opencv", f"opencv {cv2.__version__}, JPEG: {_jpeg_line_of_opencv(cv2)}", "HxW", encode, decode)


def simplejpeg() -> Contender:
    import simplejpeg as sj

    def encode(image, quality):
        if image.ndim == 2:  # it wants HxWx1: a view, no copy
            return sj.encode_jpeg(image[..., None], quality, colorspace="GRAY", colorsubsampling="Gray")
        return sj.encode_jpeg(image, quality, colorspace="BGR", colorsubsampling="420")

    def decode(data, like):
        return sj.decode_jpeg(data, colorspace="GRAY" if like.ndim == 2 else "BGR")

    return Contender(
        "simplejpeg",
        f"simplejpeg {sj.__version__}; encodes with the fast DCT below q96 "
        "(TurboJPEG's default; fastdct=False does not change it)",
        "HxWx1 only (a view of HxW)",
        encode,
        decode,
    )


def turbojpeg(accurate: bool = True) -> Contender:
    import turbojpeg as tj

    codec = tj.TurboJPEG()  # OSError without libturbojpeg, RuntimeError if its version does not fit
    # TurboJPEG takes the fast DCT below quality 96 unless told otherwise: OpenCV's JPEG needs the flag
    flags = tj.TJFLAG_ACCURATEDCT if accurate else 0

    def encode(image, quality):
        if image.ndim == 2:
            return codec.encode(image, quality, pixel_format=tj.TJPF_GRAY, jpeg_subsample=tj.TJSAMP_GRAY, flags=flags)
        return codec.encode(image, quality, pixel_format=tj.TJPF_BGR, jpeg_subsample=tj.TJSAMP_420, flags=flags)

    def decode(data, like):
        return codec.decode(data, pixel_format=tj.TJPF_GRAY if like.ndim == 2 else tj.TJPF_BGR)

    library = ctypes.util.find_library("turbojpeg") or "libturbojpeg"
    return Contender(
        "turbojpeg" if accurate else "turbojpeg-fastdct",
        f"PyTurboJPEG {tj.__version__} over the system's {library}, "
        + ("accurate DCT (TJFLAG_ACCURATEDCT)" if accurate else "its default DCT: fast below q96"),
        "HxW",
        encode,
        decode,
    )


def fxis() -> Contender:
    from fxis_shm.wire import encoding

    return Contender(
        "fxis",
        "fxis_shm.wire.encoding.encode / decode",
        "HxW",
        lambda image, q: encoding.encode(image, encoding.JPEG, q),
        lambda data, like: encoding.decode(data, encoding.JPEG, like.shape, like.dtype.name),
    )


LOADERS = {
    "opencv": opencv,
    "simplejpeg": simplejpeg,
    "turbojpeg": turbojpeg,
    "turbojpeg-fastdct": lambda: turbojpeg(accurate=False),
    "fxis": fxis,
}


def load_contenders(names: list[str]) -> list[Contender]:
    """The contenders that load; a note on stderr for each that does not."""
    loaded = []
    for name in names:
        try:
            loaded.append(LOADERS[name]())
        except (ImportError, OSError, RuntimeError) as exc:
            print(
                f"jpeg_codecs: skipping {name}: {common.describe_error(exc)} "
                f"(pip install -e '.[bench]' and scripts/install-system-packages.sh install it)",
                file=sys.stderr,
            )
    return loaded
