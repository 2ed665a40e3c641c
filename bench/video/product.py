"""The product's own video path over a list of frames, for the video benches: the encoder
``fxis record --codec`` would choose and configure (fxis_shm.formats.videotracks.VideoPlan, with
``--encoder software``: this machine has no hardware encoder), fed as the recorder feeds it, the
CPU time it took (user + system, every thread of this process), and the frames decoded back.
Not a bench: imported by bench/video/sizes.py and bench/video/anchor.py.
"""

from __future__ import annotations

import resource
from dataclasses import dataclass

import numpy as np

from fxis_shm.formats.videotracks import VideoPlan, VideoSettings

CAMERA = "scene"
DECODERS = {"h264": "h264", "h265": "hevc", "av1": "libdav1d"}  # FFmpeg's decoders, bundled by PyAV


@dataclass
class Encoded:
    plan: VideoPlan
    packets: list[bytes]
    keyframes: int
    cpu_s: float


def cpu_seconds() -> float:
    """User + system CPU time of this process so far (all its threads)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def plan_for(codec: str, frames: list[np.ndarray], fps: float) -> VideoPlan:
    """What ``fxis record --codec CODEC --encoder software`` with its defaults would use."""
    height, width = frames[0].shape[:2]
    camera = {"shape": list(frames[0].shape), "dtype": frames[0].dtype.name, "fps": fps}
    assert (width, height) == (camera["shape"][1], camera["shape"][0])
    return VideoPlan.make(VideoSettings(codec, encoder="software"), {CAMERA: camera})


def encode(codec: str, frames: list[np.ndarray], fps: float) -> Encoded:
    """Every frame through one StreamEncoder, stamped 1/fps apart, and the CPU time it took."""
    plan = plan_for(codec, frames, fps)
    encoder = plan.stream_encoder(CAMERA)
    period_ns = round(1e9 / fps)
    packets = []
    cpu0 = cpu_seconds()
    for i, image in enumerate(frames):
        packets += encoder.encode(image, i * period_ns, i, 1)
    packets += encoder.finish()
    cpu = cpu_seconds() - cpu0
    if len(packets) != len(frames):
        raise RuntimeError(f"{codec}: {len(frames)} frames in, {len(packets)} packets out")
    return Encoded(plan, [p.data for p in packets], sum(p.keyframe for p in packets), cpu)


def decode(codec: str, packets: list[bytes]) -> list[np.ndarray]:
    """The packets decoded back to 8-bit gray, as a player shows them."""
    import av

    decoder = av.CodecContext.create(DECODERS[codec], "r")
    frames = []
    for data in [*packets, None]:
        for frame in decoder.decode(None if data is None else av.Packet(data)):
            frames.append(frame.to_ndarray(format="gray"))
    return frames
