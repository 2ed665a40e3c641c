"""What a service's rings take in /dev/shm: planned from the camera options before anything
starts (where they say a frame's size and rate, as a synthetic camera's do), checked against
the room /dev/shm has, and read back from the segments once the cameras run.

A camera whose frame size only shows when it opens (a GigE camera left at its defaults)
is checked by its worker, just before it creates its ring (fxis_shm.shm.history).
"""

from __future__ import annotations

import os

from fxis_shm.errors import ConfigError
from fxis_shm.service.config import CameraSpec, ServiceConfig
from fxis_shm.shm import history, naming
from fxis_shm.shm.ring import FrameLayout, segment_size

_CHANNELS = {"mono8": 1, "bgr8": 3}


def planned_bytes(camera: CameraSpec, config: ServiceConfig) -> int | None:
    """The ring's size, if the options say the frame's size and rate (None: known at open)."""
    o = camera.options
    channels = _CHANNELS.get(o.get("pixel_format") or "mono8")
    if not (o.get("width") and o.get("height") and o.get("fps") and channels):
        return None
    slots = history.slots_for(o.get("history") or config.history, round(1e9 / o["fps"]), config.slots)
    return segment_size(FrameLayout(o["height"], o["width"], channels), slots)[0]


def check_room(config: ServiceConfig) -> None:
    """ConfigError naming every planned ring and the total if /dev/shm cannot hold them."""
    planned = {c.name: planned_bytes(c, config) for c in config.cameras}
    total = sum(b for b in planned.values() if b)
    free = history.shm_free_bytes()
    if total > free:
        each = ", ".join(f"{name} {history.mib(b)}" for name, b in planned.items() if b)
        raise ConfigError(
            f"the rings need {history.mib(total)} ({each}) and {naming.SHM_DIR} has {history.mib(free)} free: "
            f"ask for less history (--history, history=, --slots); {history.room_hint(total)}"
        )


def ring_lines(config: ServiceConfig) -> list[str]:
    """For the start-up banner: each ring's size as created, and the total."""
    sizes = {}
    for camera in config.cameras:
        path = os.path.join(naming.SHM_DIR, naming.ring_name(config.name, camera.name).lstrip("/"))
        try:
            sizes[camera.name] = os.stat(path).st_size
        except OSError:
            continue
    each = ", ".join(f"{name} {history.mib(size)}" for name, size in sizes.items())
    return [f"  rings in {naming.SHM_DIR}/fxis.{config.name}.*: {each}; {history.mib(sum(sizes.values()))} in all"]
