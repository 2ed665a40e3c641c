"""Run in .venv-lerobot (lerobot 0.4.4 with lerobot_camera_fxis) by test_lerobot.py: LeRobot
finds the plugin, builds the cameras from config dicts and reads them as a robot does; prints
one JSON object (what it saw) for the test to check.

    .venv-lerobot/bin/python tests/integration/lerobot_reads.py '{"cameras": {...}, "ticks": 40, "fps": 30}'
"""

import json
import sys
import time

import draccus
import numpy as np
from lerobot.cameras.configs import CameraConfig
from lerobot.cameras.utils import make_cameras_from_configs
from lerobot.utils.import_utils import register_third_party_plugins

from fxis_shm import read_stamp


def stamp_of(image: np.ndarray) -> int | None:
    """The frame id in a synthetic camera's pixels: mono8 became 3 equal channels."""
    return read_stamp(np.ascontiguousarray(image[:, :, 0]))


def main(spec: dict) -> dict:
    register_third_party_plugins()
    configs = {key: draccus.decode(CameraConfig, conf) for key, conf in spec["cameras"].items()}
    seen: dict = {"types": {key: conf.type for key, conf in configs.items()}}
    wrong = draccus.decode(CameraConfig, {**next(iter(spec["cameras"].values())), "width": 1})
    try:
        make_cameras_from_configs({"wrong": wrong})["wrong"].connect()
    except RuntimeError as exc:
        seen["wrong_width"] = str(exc)
    cameras = make_cameras_from_configs(configs)
    seen["classes"] = {key: type(cam).__name__ for key, cam in cameras.items()}
    for cam in cameras.values():
        cam.connect()
    first_images, ticks = None, []
    period = 1 / spec["fps"]
    next_tick = time.monotonic()
    for _ in range(spec["ticks"]):
        next_tick += period
        time.sleep(max(0.0, next_tick - time.monotonic()))  # the control loop's rate, as record_loop keeps it
        images = {key: cam.read_latest() for key, cam in cameras.items()}
        first_images = first_images or images
        ticks.append(
            {
                key: {
                    "stamp": stamp_of(image),
                    "shape": list(image.shape),
                    "record": vars(cameras[key].last_record),
                }
                for key, image in images.items()
            }
        )
    seen["ticks"] = ticks
    seen["kept_stamps"] = {key: stamp_of(image) for key, image in first_images.items()}
    found = type(next(iter(cameras.values()))).find_cameras(spec["find_endpoints"], *spec["keys"])
    seen["found"] = sorted(c["name"] for c in found)
    for cam in cameras.values():
        cam.disconnect()
    seen["connected_after"] = [cam.is_connected for cam in cameras.values()]
    return seen


def behaviour(spec: dict) -> dict:
    """How one camera answers as LeRobot's cameras document: errors, colour order, rotation."""

    register_third_party_plugins()
    conf = spec["camera"]
    seen: dict = {}

    def make(**changes):
        return make_cameras_from_configs({"cam": draccus.decode(CameraConfig, {**conf, **changes})})["cam"]

    def error_of(call) -> str:
        try:
            call()
        except Exception as exc:  # the kind is what is checked
            return type(exc).__name__
        return "none"

    cam = make()
    seen["read_before_connect"] = error_of(cam.read_latest)
    cam.connect()
    seen["connect_twice"] = error_of(cam.connect)
    seen["too_old"] = error_of(lambda: cam.read_latest(max_age_ms=0))
    rgb = cam.async_read(timeout_ms=5000)
    cam.disconnect()
    seen["disconnect_twice"] = error_of(cam.disconnect)
    bgr_cam = make(color_mode="bgr")
    bgr_cam.connect()
    bgr = bgr_cam.read()
    bgr_cam.disconnect()
    seen["stamp_bgr"] = read_stamp(bgr)  # fxis's bgr8 as stored: the stamp reads
    seen["stamp_rgb_reversed"] = read_stamp(np.ascontiguousarray(rgb[:, :, ::-1]))
    turned = make(rotation=90, width=conf["height"], height=conf["width"])
    turned.connect()
    seen["rotated_shape"] = list(turned.read().shape)
    turned.disconnect()
    seen["unknown_camera"] = error_of(lambda: make(camera="nosuch").connect())
    return seen


if __name__ == "__main__":
    request = json.loads(sys.argv[1])
    print(json.dumps(behaviour(request) if request.get("behaviour") else main(request)))
