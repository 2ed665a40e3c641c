"""A camera's calibration as ROS's camera_info_manager reads it (the YAML file that
``camera_calibration`` writes: image_width, image_height, camera_name, camera_matrix,
distortion_model, distortion_coefficients, rectification_matrix, projection_matrix), and the
sensor_msgs/CameraInfo contents made from it.

Pure apart from reading the file: text in, numbers out; ValueError naming what is wrong.
Without a calibration a camera's CameraInfo holds its size and zero matrices, which ROS
tools read as "not calibrated".
"""

from __future__ import annotations

from dataclasses import dataclass

_MATRICES = {  # key -> (rows, cols) the file must give
    "camera_matrix": (3, 3),
    "rectification_matrix": (3, 3),
    "projection_matrix": (3, 4),
}


@dataclass(frozen=True)
class Calibration:
    width: int
    height: int
    distortion_model: str = ""
    d: tuple[float, ...] = ()
    k: tuple[float, ...] = (0.0,) * 9
    r: tuple[float, ...] = (0.0,) * 9
    p: tuple[float, ...] = (0.0,) * 12
    camera_name: str = ""

    @property
    def calibrated(self) -> bool:
        return any(self.k)


def uncalibrated(width: int, height: int) -> Calibration:
    return Calibration(width, height)


def parse_calibration(text: str, source: str = "calibration") -> Calibration:
    """The calibration a camera_info_manager YAML file holds; ValueError saying what is wrong."""
    try:
        import yaml
    except ImportError:
        raise ValueError("reading a calibration file needs PyYAML: pip install 'fxis-shm[ros2]'") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ValueError(f"{source} is not YAML: {exc}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{source} is not a camera_info_manager calibration (a YAML mapping)")
    width, height = (_whole(data, key, source) for key in ("image_width", "image_height"))
    k, r, p = (_matrix(data, key, source, shape) for key, shape in _MATRICES.items())
    d = _matrix(data, "distortion_coefficients", source) if "distortion_coefficients" in data else ()
    return Calibration(
        width,
        height,
        str(data.get("distortion_model") or ("plumb_bob" if d else "")),
        d,
        k,
        r,
        p,
        str(data.get("camera_name") or ""),
    )


def read_calibration(path: str) -> Calibration:
    try:
        with open(path, encoding="utf-8") as f:
            return parse_calibration(f.read(), path)
    except OSError as exc:
        raise ValueError(f"{path}: {exc.strerror}") from None


def _whole(data: dict, key: str, source: str) -> int:
    value = data.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise ValueError(f"{source}: {key} must be a whole number of pixels > 0, got {value!r}")
    return value


def _matrix(data: dict, key: str, source: str, shape: tuple[int, int] | None = None) -> tuple[float, ...]:
    """The numbers of a {rows, cols, data} entry, checked against ``shape`` if given."""
    entry = data.get(key)
    values = entry.get("data") if isinstance(entry, dict) else None
    if not isinstance(values, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        raise ValueError(f"{source}: {key} must be a mapping with data: a list of numbers")
    if shape is not None and (len(values) != shape[0] * shape[1] or (entry.get("rows"), entry.get("cols")) != shape):
        raise ValueError(f"{source}: {key} must be {shape[0]}x{shape[1]} (rows, cols and data), got {entry!r}")
    return tuple(float(v) for v in values)
