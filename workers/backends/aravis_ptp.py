"""Read a camera's PTP state through Aravis (the logic and the feature names are in
fxis_shm/core/ptp.py). Aravis has no PTP API of its own: its maintainer's advice is to use
the GenICam features, which is what this does."""

from __future__ import annotations

from fxis_shm.core.ptp import PtpState, read_ptp


def camera_ptp(cam, GLib) -> PtpState:
    """The PTP state of an open ``Aravis.Camera``; a feature the camera lacks, or fails to
    read, counts as absent."""
    device = cam.get_device()
    genicam = device.get_genicam()

    def read(name: str) -> str | None:
        node = genicam.get_node(name)
        if node is None or not hasattr(node, "get_value_as_string"):
            return None
        try:
            return node.get_value_as_string()
        except GLib.Error:
            return None

    def execute(name: str) -> bool:
        if genicam.get_node(name) is None:
            return False
        try:
            device.execute_command(name)
        except GLib.Error:
            return False
        return True

    return read_ptp(read, execute)
