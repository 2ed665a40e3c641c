"""fxis-shm cameras for LeRobot (docs/lerobot.md). Importing the package registers the camera
type ``fxis`` with LeRobot's ``CameraConfig``; ``make_cameras_from_configs`` then finds
``FxisCamera`` here (the config class's name minus ``Config``)."""

from lerobot_camera_fxis.config_fxis import FxisCameraConfig
from lerobot_camera_fxis.fxis import FxisCamera
from lerobot_camera_fxis.ticks import TickRecord, capture_time_features

__all__ = ["FxisCamera", "FxisCameraConfig", "TickRecord", "capture_time_features"]
