"""Camera backends by kind. Modules load only when their kind is used, so an
optional SDK binding that is not installed only matters to its own cameras."""
from __future__ import annotations

import importlib

from fxis_shm.errors import ConfigError

BACKENDS = {
    "synthetic": "fxis_shm.workers.backends.synthetic:SyntheticCamera",
    "aravis": "fxis_shm.workers.backends.aravis:AravisCamera",  # GigE Vision, USB3 Vision
    "genicam": "fxis_shm.workers.backends.genicam:GenicamCamera",  # any GenTL producer
    "opencv": "fxis_shm.workers.backends.opencv:OpenCVCamera",  # cv2.VideoCapture
    "bag": "fxis_shm.workers.backends.bag:BagCamera",  # a recorded topic (fxis record), replayed
}


def discover_all() -> tuple[list[dict], dict[str, str]]:
    """Every camera reachable through the installed backends, and why a backend
    could not look (its optional dependency is missing, say)."""
    found, unavailable = [], {}
    for kind in BACKENDS:
        try:
            found += [{"kind": kind, **cam} for cam in backend_class(kind).discover()]
        except Exception as exc:  # a missing SDK binding must not hide the other backends
            unavailable[kind] = f"{type(exc).__name__}: {exc}"
    return found, unavailable


def backend_class(kind: str):
    try:
        path = BACKENDS[kind]
    except KeyError:
        raise ConfigError(f"unknown camera kind {kind!r}; known kinds: {', '.join(BACKENDS)}") from None
    module, _, cls = path.partition(":")
    return getattr(importlib.import_module(module), cls)
