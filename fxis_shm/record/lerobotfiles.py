"""The files of a LeRobotDataset v3.0 (the layout lerobot 0.4.4 reads: lerobot/datasets/utils.py),
written with pyarrow and PyAV, without lerobot or torch:

    meta/info.json, meta/stats.json, meta/tasks.parquet, meta/episodes/chunk-000/file-000.parquet
    data/chunk-000/file-000.parquet
    videos/KEY/chunk-000/file-000.mp4

One episode, one file of each. Videos are H.264 (libx264, which LeRobot names ``h264``),
``yuv420p``, a keyframe every 2 frames as LeRobot's own encoder writes them (a frame decodes
from at most one frame before it), constant frame rate: frame i at pts i/fps, which is where
LeRobot's decoder looks for the frame of ``timestamp`` i/fps.
"""

from __future__ import annotations

import json
import os
from fractions import Fraction

import numpy as np

from fxis_shm.errors import ConfigError

CODEBASE_VERSION = "v3.0"
CHUNK = "chunk-000/file-000"
VIDEO_CODEC, PIX_FMT, KEYFRAME_EVERY, CRF = "h264", "yuv420p", 2, 23
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
EXTRA = "fxis-shm[lerobot]' (pyarrow) and 'fxis-shm[video]' (PyAV)"


def require_pyarrow():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError as exc:
        raise ConfigError(f"a LeRobot export needs pyarrow ({exc}): pip install '{EXTRA}") from None
    return pa, pq


class VideoWriter:
    """``add(rgb)`` each frame in order; ``close()``; ``stats`` per channel in [0, 1]."""

    def __init__(self, path: str, fps: int, width: int, height: int):
        from fxis_shm.formats.videoencoder import require_av

        if width % 2 or height % 2:
            raise ConfigError(f"{path}: frames of {width}x{height}: yuv420p video needs an even width and height")
        self._av = require_av()
        os.makedirs(os.path.dirname(path), exist_ok=True)
        self._container = self._av.open(path, "w", format="mp4")
        self._stream = self._container.add_stream("libx264", rate=Fraction(fps))
        self._stream.width, self._stream.height, self._stream.pix_fmt = width, height, PIX_FMT
        self._stream.time_base = Fraction(1, fps)
        self._stream.options = {"g": str(KEYFRAME_EVERY), "crf": str(CRF), "bf": "0"}
        self._count = 0
        self.stats = ImageStats()

    def add(self, rgb: np.ndarray) -> None:
        frame = self._av.VideoFrame.from_ndarray(rgb, format="rgb24").reformat(format=PIX_FMT)
        frame.pts = self._count
        self._count += 1
        self._container.mux(self._stream.encode(frame))
        self.stats.add(rgb)

    def close(self) -> None:
        self._container.mux(self._stream.encode(None))
        self._container.close()


class ImageStats:
    """Per-channel min, max, mean and std of RGB frames scaled to [0, 1], shaped (3, 1, 1) as
    LeRobot keeps an image feature's stats."""

    def __init__(self):
        self.count = 0
        self._sum = np.zeros(3)
        self._squares = np.zeros(3)
        self._min = np.full(3, 255.0)
        self._max = np.zeros(3)
        self._pixels = 0

    def add(self, rgb: np.ndarray) -> None:
        values = rgb.reshape(-1, 3).astype(np.float64)
        self._sum += values.sum(axis=0)
        self._squares += (values**2).sum(axis=0)
        self._min = np.minimum(self._min, values.min(axis=0))
        self._max = np.maximum(self._max, values.max(axis=0))
        self._pixels += len(values)
        self.count += 1

    def as_dict(self) -> dict:
        mean = self._sum / self._pixels
        std = np.sqrt(np.maximum(self._squares / self._pixels - mean**2, 0))

        def shaped(v):
            return (v / 255.0).reshape(3, 1, 1).tolist()

        return {"min": shaped(self._min), "max": shaped(self._max), "mean": shaped(mean), "std": shaped(std)} | {
            "count": [self.count]
        }


def column_stats(values: np.ndarray) -> dict:
    """min, max, mean, std, count and LeRobot's quantiles of one numeric column (per element)."""
    v = values.reshape(len(values), -1).astype(np.float64)
    stats = {
        "min": values.reshape(len(values), -1).min(axis=0).tolist(),
        "max": values.reshape(len(values), -1).max(axis=0).tolist(),
        "mean": v.mean(axis=0).tolist(),
        "std": v.std(axis=0).tolist(),
        "count": [len(values)],
    }
    for q in QUANTILES:
        stats[f"q{round(q * 100):02d}"] = np.quantile(v, q, axis=0).tolist()
    return stats


def write_data(root: str, columns: dict[str, np.ndarray]) -> None:
    """data/chunk-000/file-000.parquet: one row per frame; a 1-wide column as a scalar, a
    wider one as a fixed-size list (as LeRobot writes them)."""
    pa, pq = require_pyarrow()
    arrays = {}
    for name, values in columns.items():
        if values.ndim == 1:
            arrays[name] = pa.array(values)
        else:
            flat = pa.array(values.reshape(-1))
            arrays[name] = pa.FixedSizeListArray.from_arrays(flat, values.shape[1])
    path = os.path.join(root, "data", CHUNK + ".parquet")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    pq.write_table(pa.table(arrays), path)


def write_tasks(root: str, tasks: list[str]) -> None:
    """meta/tasks.parquet: the task strings as the pandas index LeRobot reads (task -> task_index)."""
    pa, pq = require_pyarrow()
    pandas_meta = {
        "index_columns": ["__index_level_0__"],
        "column_indexes": [],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64"},
            {"name": None, "field_name": "__index_level_0__", "pandas_type": "unicode", "numpy_type": "object"},
        ],
    }
    table = pa.table({"task_index": pa.array(range(len(tasks)), pa.int64()), "__index_level_0__": tasks})
    table = table.replace_schema_metadata({"pandas": json.dumps(pandas_meta)})
    pq.write_table(table, os.path.join(root, "meta", "tasks.parquet"))


def write_episode(root: str, tasks: list[str], length: int, fps: int, video_keys: list[str]) -> None:
    """meta/episodes/chunk-000/file-000.parquet: the one episode, where its rows and videos are."""
    pa, pq = require_pyarrow()
    row: dict = {"episode_index": [0], "tasks": [tasks], "length": [length]}
    row |= {"data/chunk_index": [0], "data/file_index": [0], "dataset_from_index": [0], "dataset_to_index": [length]}
    for key in video_keys:
        row |= {f"videos/{key}/chunk_index": [0], f"videos/{key}/file_index": [0]}
        row |= {f"videos/{key}/from_timestamp": [0.0], f"videos/{key}/to_timestamp": [length / fps]}
    row |= {"meta/episodes/chunk_index": [0], "meta/episodes/file_index": [0]}
    path = os.path.join(root, "meta", "episodes", CHUNK + ".parquet")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    pq.write_table(pa.table(row), path)


def video_feature(height: int, width: int, fps: int) -> dict:
    info = {"video.height": height, "video.width": width, "video.codec": VIDEO_CODEC, "video.pix_fmt": PIX_FMT}
    info |= {"video.is_depth_map": False, "video.fps": fps, "video.channels": 3, "has_audio": False}
    return {"dtype": "video", "shape": [height, width, 3], "names": ["height", "width", "channels"], "info": info}


def write_info(root: str, fps: int, frames: int, features: dict, fxis: dict) -> None:
    """meta/info.json; ``fxis`` (the bag, its clock, what was dropped) is kept beside LeRobot's keys."""
    info = {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": None,
        "total_episodes": 1,
        "total_frames": frames,
        "total_tasks": 1,
        "chunks_size": 1000,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 200,
        "fps": fps,
        "splits": {"train": "0:1"},
        "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
        "video_path": "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4",
        "features": features,
        "fxis": fxis,
    }
    with open(os.path.join(root, "meta", "info.json"), "w") as f:
        json.dump(info, f, indent=4)


def write_stats(root: str, stats: dict) -> None:
    with open(os.path.join(root, "meta", "stats.json"), "w") as f:
        json.dump(stats, f, indent=4)
