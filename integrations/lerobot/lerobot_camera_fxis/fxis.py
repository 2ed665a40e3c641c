"""``FxisCamera``: a LeRobot camera whose frames come from an fxis service, one synchronized
tuple per control tick for all the fxis cameras of a robot (lerobot_camera_fxis.ticks)."""

from __future__ import annotations

import time
from typing import Any

import cv2
import numpy as np
from lerobot.cameras.camera import Camera
from lerobot.cameras.configs import ColorMode
from lerobot.cameras.utils import get_cv2_rotation
from lerobot.utils.errors import DeviceAlreadyConnectedError, DeviceNotConnectedError

from fxis_shm import Client, ClientKeys, FrameTimeout, FxisError, RequestTimeout
from lerobot_camera_fxis.config_fxis import FxisCameraConfig
from lerobot_camera_fxis.ticks import TickRecord, TupleSource, source_for

DEFAULT_ENDPOINT = "tcp://127.0.0.1:5555"


class FxisCamera(Camera):  # type: ignore[misc]
    """A camera of an fxis service, read as LeRobot's cameras are (read, async_read,
    read_latest), each image a copy in ``color_mode`` (RGB by default) after ``rotation``."""

    def __init__(self, config: FxisCameraConfig):
        super().__init__(config)
        self.config = config
        self.color_mode = ColorMode(config.color_mode)
        self.rotation: int | None = get_cv2_rotation(config.rotation)
        self._source: TupleSource | None = None
        self._period_ns = 0
        self.last_record: TickRecord | None = None

    def __str__(self) -> str:
        return f"{self.__class__.__name__}({self.config.camera})"

    @property
    def is_connected(self) -> bool:
        return self._source is not None

    @property
    def source(self) -> TupleSource:
        """The client and tuples this camera shares with the robot's other fxis cameras."""
        if self._source is None:
            raise DeviceNotConnectedError(f"{self} is not connected.")
        return self._source

    @staticmethod
    def find_cameras(
        endpoint: str | list[str] = DEFAULT_ENDPOINT, server_key: str | None = None, client_key: str | None = None
    ) -> list[dict[str, Any]]:
        """The cameras of the fxis service(s) at ``endpoint`` (default: the default service),
        with CurveZMQ key files where the service needs them."""
        keys = ClientKeys.from_files(server_key, client_key) if server_key and client_key else None
        with Client(endpoint, timeout=5.0, keys=keys) as client:
            cameras = client.status()["cameras"]
        return [
            {
                "name": name,
                "type": "fxis",
                "id": name,
                "endpoint": info.get("service", endpoint),
                "default_stream_profile": {
                    "width": info["shape"][1],
                    "height": info["shape"][0],
                    "fps": info["fps"],
                    "channels": info["shape"][2] if len(info["shape"]) == 3 else 1,
                },
            }
            for name, info in cameras.items()
        ]

    def connect(self, warmup: bool = True) -> None:
        if self.is_connected:
            raise DeviceAlreadyConnectedError(f"{self} is already connected.")
        c = self.config
        source = source_for(
            (c.endpoints, c.server_key, c.client_key, c.sync, c.max_skew_ms, c.capture_lead_ms, c.request_timeout_s)
        )
        try:
            self._check_against_service(source)
        except Exception:
            if not source.members:
                source.leave(c.camera)  # closes the client this camera alone made
            raise
        source.join(c.camera, self._period_ns)
        self._source = source
        if warmup:  # one frame of this camera alone, through the colour and rotation steps; no tick
            try:
                frame = source.client.image(c.camera, wait="next", timeout=c.warmup_s)
                self._postprocess(frame.image, None)
            except FxisError as exc:
                self.disconnect()
                raise TimeoutError(f"{self}: no frame within warmup_s={c.warmup_s}: {exc}") from exc

    def _check_against_service(self, source: TupleSource) -> None:
        """Width, height and fps as configured (LeRobot fixed its features' shapes from them)."""
        try:
            cameras = source.client.status()["cameras"]
        except FxisError as exc:
            raise ConnectionError(f"{self}: no answer from fxis at {self.config.endpoint}: {exc}") from exc
        if self.config.camera not in cameras:
            raise ValueError(
                f"{self}: the fxis service has no camera {self.config.camera!r} (it has {sorted(cameras)})"
            )
        info = cameras[self.config.camera]
        height, width = info["shape"][:2]
        if self.rotation in (cv2.ROTATE_90_CLOCKWISE, cv2.ROTATE_90_COUNTERCLOCKWISE):
            width, height = height, width
        fps = info["fps"]
        for name, want, have in (("width", self.width, width), ("height", self.height, height)):
            if want is not None and want != have:
                raise RuntimeError(f"{self}: configured {name}={want}, but the fxis camera gives {name}={have}")
        if self.fps is not None and fps and abs(self.fps - fps) > 0.01 * self.fps:
            raise RuntimeError(f"{self}: configured fps={self.fps}, but the fxis camera runs at fps={fps}")
        self.width, self.height = width, height
        self._period_ns = round(1e9 / (fps or self.fps or 30))
        if self.fps is None and fps:
            self.fps = round(fps)

    def read(self, color_mode: ColorMode | None = None) -> np.ndarray:
        """A frame of a new tuple (blocking up to the request timeout)."""
        return self._read(False, self.config.request_timeout_s, color_mode)

    def async_read(self, timeout_ms: float = 200) -> np.ndarray:
        """A frame of the next tuple, waiting for new frames up to ``timeout_ms`` (TimeoutError)."""
        return self._read(False, timeout_ms / 1e3, None)

    def read_latest(self, max_age_ms: int = 500) -> np.ndarray:
        """This tick's frame, of the best tuple already stored (TupleSource.take), without
        waiting for new frames. TimeoutError when the frame is older than ``max_age_ms``."""
        frame_image, record = self._take(True, None)
        age_ms = (time.monotonic_ns() - record.t_capture[self.config.camera]) / 1e6
        if age_ms > max_age_ms:
            raise TimeoutError(f"{self} latest frame is too old: {age_ms:.1f} ms (max allowed: {max_age_ms} ms).")
        return self._postprocess(frame_image, None)

    def _read(self, stored: bool, timeout_s: float | None, color_mode: ColorMode | None) -> np.ndarray:
        frame_image, _ = self._take(stored, timeout_s)
        return self._postprocess(frame_image, color_mode)

    def _take(self, stored: bool, timeout_s: float | None) -> tuple[np.ndarray, TickRecord]:
        try:
            frame, record = self.source.take(self.config.camera, stored=stored, timeout_s=timeout_s)
        except (FrameTimeout, RequestTimeout) as exc:
            raise TimeoutError(f"Timed out waiting for frame from camera {self}: {exc}") from exc
        except FxisError as exc:
            raise RuntimeError(f"{self}: {exc}") from exc
        self.last_record = record
        return frame.image, record

    def _postprocess(self, image: np.ndarray, color_mode: ColorMode | None) -> np.ndarray:
        """A new array LeRobot may keep: 3 channels in the colour order asked, rotated."""
        mode = ColorMode(color_mode) if color_mode is not None else self.color_mode
        if image.ndim == 2 or image.shape[2] == 1:
            out = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)  # the same bytes in either order
        elif mode == ColorMode.RGB:
            out = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)  # fxis stores colour as BGR
        else:
            out = np.array(image, copy=True)
        if self.rotation is not None:
            out = cv2.rotate(out, self.rotation)
        return out

    def disconnect(self) -> None:
        if self._source is None:
            raise DeviceNotConnectedError(f"{self} is not connected.")
        source, self._source = self._source, None
        source.leave(self.config.camera)
