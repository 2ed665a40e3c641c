"""Which way the bridge joins the ROS 2 graph (``ros2_via``), and its node's name.

* ``rclpy``: a real ROS 2 node (fxis_shm.ros2.rclpynode) on the RMW the host's ROS 2 runs. Nodes
  on the same host get frames through their RMW's own shared memory; the bridge is in
  ``ros2 node list``. Needs rclpy: a sourced ROS 2, or ROS 2's wheels in the bridge's Python.
* ``cyclone``: a plain Cyclone DDS participant (fxis_shm.ros2.dds) that follows ROS 2's
  conventions; needs no ROS install. Every sample travels as UDP datagrams, also on one host.
* ``auto``: rclpy where it imports, else cyclone.
"""

from __future__ import annotations

import re
import sys

from fxis_shm.errors import ConfigError

NODE_PREFIX = "fxis_"


def choose_via(via: str, rclpy_error: str | None) -> str:
    """ "rclpy" or "cyclone" for setting ``via``, given why rclpy does not import (None: it does)."""
    if via == "cyclone" or (via == "auto" and rclpy_error is not None):
        return "cyclone"
    if rclpy_error is not None:
        raise ConfigError(
            f"ros2_via = rclpy, but {sys.executable} cannot import rclpy ({rclpy_error}): source a ROS 2 "
            "install before fxis run, or give the bridge a ROS 2 Python with ros2_python (docs/ros2.md)"
        )
    return "rclpy"


def node_name(service: str) -> str:
    """The bridge's ROS node name for service ``service``: ``fxis_`` and the service's name with
    every character a ROS name cannot hold made ``_`` (a node name is [A-Za-z0-9_])."""
    return NODE_PREFIX + re.sub(r"[^A-Za-z0-9_]", "_", service)


def open_participant(via: str, domain: int, namespace: str, service: str):
    """The bridge's participant: an rclpy node or a Cyclone participant, as ``via`` decides."""
    from fxis_shm.ros2.rclpynode import rclpy_available

    chosen = choose_via(via, None if via == "cyclone" else rclpy_available())
    if chosen == "rclpy":
        from fxis_shm.ros2.rclpynode import RclpyNode

        return RclpyNode(domain, node_name(service), namespace)
    from fxis_shm.ros2.dds import RosParticipant
    from fxis_shm.ros2.vendors import bridge_config

    participant = RosParticipant(domain, bridge_config())
    participant.announce_node(node_name(service), namespace)
    return participant
