"""Camera backends by kind. Modules load only when their kind is used, so an
optional SDK binding that is not installed only matters to its own cameras."""
from __future__ import annotations

import importlib

from fxis_shm.errors import ConfigError

BACKENDS = {
    "synthetic": "fxis_shm.workers.backends.synthetic:SyntheticCamera",
}


def backend_class(kind: str):
    try:
        path = BACKENDS[kind]
    except KeyError:
        raise ConfigError(f"unknown camera kind {kind!r}; known kinds: {', '.join(BACKENDS)}") from None
    module, _, cls = path.partition(":")
    return getattr(importlib.import_module(module), cls)
