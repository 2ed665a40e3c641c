"""Which way the bridge joins the ROS 2 graph (fxis_shm.ros2.participants) and the settings that
choose it (fxis_shm.service.ros2config): pure decisions, no DDS."""

import pytest

from fxis_shm.errors import ConfigError
from fxis_shm.ros2.participants import choose_via, node_name
from fxis_shm.ros2.vendors import CONFIG_ENV, INTEROP_XML, bridge_config, use_fastdds_transports
from fxis_shm.service.ros2config import ros2_settings


def test_auto_takes_rclpy_where_it_imports_and_cyclone_elsewhere():
    assert choose_via("auto", None) == "rclpy"
    assert choose_via("auto", "ModuleNotFoundError: rclpy") == "cyclone"
    assert choose_via("cyclone", None) == "cyclone"
    assert choose_via("rclpy", None) == "rclpy"


def test_rclpy_asked_for_where_it_does_not_import_says_what_to_do():
    with pytest.raises(ConfigError, match="cannot import rclpy .*ros2_python"):
        choose_via("rclpy", "ModuleNotFoundError: No module named 'rclpy'")


def test_the_node_name_is_the_services_made_a_ros_name():
    assert node_name("cell-1.left") == "fxis_cell_1_left"


def test_the_users_cyclone_settings_come_first_and_the_interop_ones_last():
    assert bridge_config({}) == INTEROP_XML
    assert bridge_config({CONFIG_ENV: "file:///etc/cyclone.xml"}) == f"file:///etc/cyclone.xml,{INTEROP_XML}"
    assert "<IgnoreTypeInformation>1.15</IgnoreTypeInformation>" in INTEROP_XML


def test_the_fastdds_transports_are_set_unless_the_user_chose():
    environ = {}
    use_fastdds_transports(environ)
    assert environ == {"FASTDDS_BUILTIN_TRANSPORTS": "DEFAULT?sockets_size=64MB"}
    mine = {"FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}
    use_fastdds_transports(mine)
    assert mine == {"FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}


def test_ros2_via_and_python_are_checked_at_start(tmp_path):
    with pytest.raises(ConfigError, match="ros2_via must be one of auto, rclpy, cyclone"):
        ros2_settings({"ros2": True, "ros2_via": "fastdds"}, ["a"])
    with pytest.raises(ConfigError, match="ros2_python .* not a Python interpreter"):
        ros2_settings({"ros2": True, "ros2_python": str(tmp_path / "nopython")}, ["a"])
    settings = ros2_settings({"ros2": True, "ros2_via": "cyclone"}, ["a"])
    assert settings is not None and (settings.via, settings.python) == ("cyclone", None)
    with pytest.raises(ConfigError, match="ros2_via set without ros2"):
        ros2_settings({"ros2_via": "rclpy"}, ["a"])
