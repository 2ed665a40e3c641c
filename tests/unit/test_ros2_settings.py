"""The ROS 2 bridge's settings and a camera's calibration file, checked before anything starts."""

from __future__ import annotations

import pytest

from fxis_shm.errors import ConfigError
from fxis_shm.formats.calibration import parse_calibration
from fxis_shm.service.config import build_config
from fxis_shm.service.ros2config import Ros2Settings, ros2_settings

GOOD = """image_width: 640
image_height: 480
camera_name: left
camera_matrix: {rows: 3, cols: 3, data: [500, 0, 320, 0, 500, 240, 0, 0, 1]}
distortion_model: rational_polynomial
distortion_coefficients: {rows: 1, cols: 8, data: [0.1, -0.2, 0, 0, 0, 0, 0, 0]}
rectification_matrix: {rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0, 0, 0, 1]}
projection_matrix: {rows: 3, cols: 4, data: [500, 0, 320, 0, 0, 500, 240, 0, 0, 0, 1, 0]}
"""


def test_a_camera_info_manager_file_gives_every_field():
    c = parse_calibration(GOOD)
    assert (c.width, c.height, c.camera_name, c.distortion_model) == (640, 480, "left", "rational_polynomial")
    assert c.k == (500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0) and len(c.d) == 8 and len(c.p) == 12
    assert c.calibrated


@pytest.mark.parametrize(
    "text, words",
    [
        ("image_width: [", "not YAML"),
        ("- a list", "YAML mapping"),
        (GOOD.replace("image_width: 640", "image_width: -1"), "image_width"),
        (GOOD.replace("rows: 3, cols: 4", "rows: 4, cols: 3"), "projection_matrix must be 3x4"),
        (GOOD.replace("data: [500, 0, 320, 0, 500, 240, 0, 0, 1]", "data: [1, 2]"), "camera_matrix must be 3x3"),
        ("\n".join(line for line in GOOD.splitlines() if "rectification" not in line), "rectification_matrix"),
    ],
)
def test_a_bad_calibration_says_what_is_wrong(text, words):
    with pytest.raises(ValueError, match=words):
        parse_calibration(text, "left.yaml")


def test_the_domain_comes_from_the_setting_then_ros_domain_id_then_zero():
    assert ros2_settings({"ros2": True, "ros2_domain": "7"}, [], {"ROS_DOMAIN_ID": "3"}).domain == 7
    assert ros2_settings({"ros2": True}, [], {"ROS_DOMAIN_ID": "3"}).domain == 3
    assert ros2_settings({"ros2": True}, [], {"ROS_DOMAIN_ID": ""}) == Ros2Settings(0, "", None)


def test_namespace_and_tuple_rate_are_normalized_and_checked():
    settings = ros2_settings({"ros2": True, "ros2_namespace": "cell1/left", "ros2_tuples": 12.5}, ["cam0"], {})
    assert (settings.namespace, settings.tuples_hz) == ("/cell1/left", 12.5)
    with pytest.raises(ConfigError, match="ROS_DOMAIN_ID"):
        ros2_settings({"ros2": True}, [], {"ROS_DOMAIN_ID": "abc"})
    with pytest.raises(ConfigError, match="camera '1cam'"):
        ros2_settings({"ros2": True}, ["1cam"], {})


def test_bridge_settings_without_the_bridge_are_refused_rather_than_ignored():
    with pytest.raises(ConfigError, match="ros2_tuples set without ros2"):
        build_config({"ros2_tuples": 5})
    assert build_config({}).ros2 is None
    assert build_config({"ros2": True, "ros2_domain": 9}).ros2 == Ros2Settings(9, "", None)
