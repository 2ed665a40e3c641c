"""The ROS 2 bridge process: the cameras on the ROS 2 graph (fxis_shm.ros2.bridge), a client
of the coordinator and of the rings like any other, supervised and restarted like the
camera workers and the coordinator."""

from __future__ import annotations

import threading

from fxis_shm.service.childspec import Ros2Spec

from ._child import Ready, child_main


def run(spec: Ros2Spec, ready: Ready, stop: threading.Event) -> None:
    from fxis_shm.ros2.bridge import Bridge

    Bridge(spec, stop).run(on_ready=ready.ok)


if __name__ == "__main__":
    child_main(Ros2Spec, run)
