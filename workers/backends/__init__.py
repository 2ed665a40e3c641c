"""Camera backends: the classes fxis_shm.service.camerakinds names, one module per kind.
A module loads only when its kind is used, so an optional SDK binding that is
not installed only matters to its own cameras."""

from __future__ import annotations

import importlib

from fxis_shm.service.camerakinds import KINDS, camera_kind


def discover_all() -> tuple[list[dict], dict[str, str]]:
    """Every camera reachable through the installed backends, and why a backend
    could not look (its optional dependency is missing, say)."""
    found, unavailable = [], {}
    for kind in KINDS:
        try:
            found += [{"kind": kind, **cam} for cam in backend_class(kind).discover()]
        except Exception as exc:  # a missing SDK binding must not hide the other backends
            unavailable[kind] = f"{type(exc).__name__}: {exc}"
    return found, unavailable


def backend_class(kind: str):
    module, cls = camera_kind(kind).backend_path
    return getattr(importlib.import_module(module), cls)
