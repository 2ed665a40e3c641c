"""ROS 2's name rules (fxis_shm.formats.rosnames), as rmw_validate_full_topic_name and
rmw_validate_namespace apply them: what passes, and for what fails, the rule the message names."""

from __future__ import annotations

import pytest

from fxis_shm.errors import InvalidArgument
from fxis_shm.formats import rosnames


@pytest.mark.parametrize("name", ["/a", "/_", "/cam0/image_raw", "/Cell_1/cam0/image_raw/compressed", "/a" * 123 + "b"])
def test_fully_qualified_topic_names_ros_accepts(name):
    assert rosnames.check_topic(name) == name


@pytest.mark.parametrize(
    "name, rule",
    [
        ("", "must not be empty"),
        ("cam0/image_raw", "must be absolute"),
        ("/", "must not end with '/'"),
        ("/cam0/", "must not end with '/'"),
        ("/cam-0/image_raw", "only letters, digits, '_' and '/': '-' at 4"),
        ("/cam0/imäge", "only letters, digits, '_' and '/': 'ä' at 8"),
        ("/~/image", "only letters"),  # substitutions are not supported
        ("/{node}/image", "only letters"),
        ("/cam0//image_raw", r"must not contain repeated '/' \(at 5\)"),
        ("/cell/0cam", r"must not have a token that starts with a digit \(at 6\)"),
        ("/0", "starts with a digit"),
        ("/a" * 123 + "bc", "must be at most 247 characters long, not 248"),
    ],
)
def test_topic_names_ros_refuses_say_which_rule(name, rule):
    with pytest.raises(InvalidArgument, match=rule) as refused:
        rosnames.check_topic(name)
    assert str(refused.value).startswith(f"topic name {name!r}")
    assert isinstance(refused.value, ValueError)


@pytest.mark.parametrize(
    "namespace, normalized",
    [("", ""), ("/", ""), ("/cell1", "/cell1"), ("cell1", "/cell1"), ("plant/cell_1", "/plant/cell_1")],
)
def test_namespaces_are_normalized_to_empty_or_absolute(namespace, normalized):
    assert rosnames.check_namespace(namespace) == normalized


@pytest.mark.parametrize(
    "namespace, rule",
    [
        ("/cell1/", "must not end with '/'"),
        ("//cell1", "repeated '/'"),
        ("/cell 1", "only letters, digits, '_' and '/': ' ' at 5"),
        ("1cell", "starts with a digit"),
        ("/" + "a" * 245, "must be at most 245 characters long, not 246"),
    ],
)
def test_namespaces_ros_refuses_say_which_rule(namespace, rule):
    with pytest.raises(InvalidArgument, match=rule) as refused:
        rosnames.check_namespace(namespace)
    assert str(refused.value).startswith("namespace ")


def test_the_longest_namespace_leaves_room_for_a_one_letter_topic():
    namespace = "/" + "a" * 244
    assert rosnames.topic(namespace, "b") == namespace + "/b"
    with pytest.raises(InvalidArgument, match="at most 247"):
        rosnames.topic(namespace, "bc")


@pytest.mark.parametrize("token", ["cam0", "_private", "Cam_0", "a"])
def test_tokens_ros_accepts(token):
    assert rosnames.check_token(token) == token


@pytest.mark.parametrize(
    "token, rule",
    [("", "must not be empty"), ("0cam", "must not start with a digit"), ("cam-0", "'-' at 3"), ("a/b", "'/' at 1")],
)
def test_tokens_ros_refuses_say_which_rule(token, rule):
    with pytest.raises(InvalidArgument, match=rule):
        rosnames.check_token(token)


def test_relative_names_are_tokens_joined_by_single_slashes():
    assert rosnames.check_relative("image_raw/compressed") == "image_raw/compressed"
    for name, rule in [("a//b", "name 'a//b': token '' must not be empty"), ("a/1b", "token '1b' must not start")]:
        with pytest.raises(InvalidArgument, match=rule):
            rosnames.check_relative(name)
    with pytest.raises(InvalidArgument, match="name '/a': token '' must not be empty"):
        rosnames.check_relative("/a")  # absolute: not relative


def test_topics_are_built_from_a_namespace_and_names():
    assert rosnames.topic("", "cam0", "image_raw") == "/cam0/image_raw"
    assert rosnames.topic("/", "cam0") == "/cam0"
    assert rosnames.topic("cell1", "cam0", "image_raw/compressed") == "/cell1/cam0/image_raw/compressed"
    assert rosnames.join("/cell1/cam0", "image_raw", "compressed") == "/cell1/cam0/image_raw/compressed"
    with pytest.raises(InvalidArgument, match="name 'cam-0' must hold only letters, digits and '_'"):
        rosnames.topic("/cell1", "cam-0", "image_raw")
    with pytest.raises(InvalidArgument, match="needs a name"):
        rosnames.topic("/cell1")
    with pytest.raises(InvalidArgument, match="must be absolute"):
        rosnames.join("cam0", "image_raw")  # a base topic is fully qualified


def test_dds_names_are_rmws():
    assert rosnames.dds_topic_name("/cam0/image_raw") == "rt/cam0/image_raw"
    assert rosnames.dds_type_name("sensor_msgs/msg/Image") == "sensor_msgs::msg::dds_::Image_"
    assert rosnames.dds_type_name("std_msgs/msg/Header") == "std_msgs::msg::dds_::Header_"
    with pytest.raises(InvalidArgument, match="must not end with '/'"):
        rosnames.dds_topic_name("/cam0/")
    for bad in ("sensor_msgs/Image", "sensor_msgs//Image", "sensor_msgs/msg/Image/x", "a/msg/Im-age"):
        with pytest.raises(InvalidArgument, match="must be package/msg/Name"):
            rosnames.dds_type_name(bad)
