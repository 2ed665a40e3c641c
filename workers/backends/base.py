"""The camera plug-in base: a backend implements open, grab and close."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from fxis_shm.core.ptp import PtpState
from fxis_shm.service.camerakinds import camera_options
from fxis_shm.shm.ring import FrameLayout


class CameraLost(Exception):
    """The camera stopped answering (unplugged, powered off, network gone). The
    worker reports it, closes the camera and reopens it with backoff."""


@dataclass
class Capture:
    """One frame as a camera delivered it. ``image`` belongs to the camera and
    is valid until the next ``grab``; the worker copies it into the ring."""

    image: np.ndarray
    frame_id: int
    t_capture: int  # ns of CLOCK_MONOTONIC


class Camera(ABC):
    """A source of frames, run inside its own camera worker process."""

    kind: ClassVar[str]  # its entry in fxis_shm.service.camerakinds, which declares its options
    note: str = ""  # a short line the worker shows as the camera's status note ("" for none)

    def __init__(self, name: str, options: Mapping[str, Any], time_origin_ns: int):
        self.name = name
        # Typed, checked and completed with defaults (options not given may be left out or None)
        self.options = camera_options(name, self.kind, {k: v for k, v in options.items() if v is not None})
        self.time_origin_ns = time_origin_ns
        self.frames_dropped = 0  # frames the camera lost before delivering them

    @abstractmethod
    def open(self) -> None:
        """Connect and start acquiring; raise with a clear message if the camera refuses."""

    @abstractmethod
    def grab(self, timeout: float) -> Capture | None:
        """The next complete frame, or None if none arrived within ``timeout`` seconds.
        Raises CameraLost if the camera is gone; incomplete frames are not returned
        but counted in ``frames_dropped``."""

    def close(self) -> None:  # noqa: B027 (not abstract: a camera with nothing to release keeps it)
        """Stop acquiring and release the device."""

    _layout: FrameLayout | None = None  # backends set these when the camera is opened
    _period_ns: int = 0

    @property
    def layout(self) -> FrameLayout | None:
        """The frame layout if known before the first frame."""
        return self._layout

    @property
    def nominal_period_ns(self) -> int:
        """The frame period the camera is set to, 0 if unknown."""
        return self._period_ns

    @classmethod
    def discover(cls) -> list[dict]:
        """Cameras this backend can reach: dicts with at least "id" (what --camera
        takes as device=...), "model" and "format". Raises if the backend's SDK
        binding is not installed."""
        return []

    @property
    def supports_trigger(self) -> bool:
        """True if the camera captures on ``trigger()`` (trigger=software) rather than free-running."""
        return self.options.get("trigger") == "software"

    def trigger(self) -> None:
        """Capture one frame now; called from another thread than ``grab``."""
        raise NotImplementedError(f"camera {self.name!r} is not software-triggered")

    def ptp(self) -> PtpState | None:
        """The camera's PTP (IEEE 1588) state, as its features say (fxis_shm/core/ptp.py); None
        for a camera that has no way to say (synthetic, a video file, a bag)."""
        return None

    # ---- settings at run time (workers/tuning.py applies them between two frames) ----

    def settings(self, extra: Iterable[str] = ()) -> dict[str, dict]:
        """Each setting the camera has now, described as fxis_shm.core.tuning.describe makes
        it: value, type, access, cost ("live": applied between two frames; "restart": the
        stream restarts with a new ring) and limits; plus the node-map features named in
        ``extra`` that it has (GenICam cameras). A camera without any: {}."""
        return {}

    def set_live(self, values: Mapping[str, Any]) -> None:
        """Apply checked live settings (called between two ``grab``); raise ValueError if the
        camera refuses one (the worker then puts back the values it had)."""
        raise ValueError(f"camera {self.name!r} ({self.kind}) changes nothing at run time")

    def features(self) -> list[dict]:
        """Every feature of the camera's node map ("name", "type", "access", its range or
        enumeration, "value"), as `arv-tool features` lists them; cameras without a node map
        list their settings."""
        return [{"name": key, **entry} for key, entry in self.settings().items()]
