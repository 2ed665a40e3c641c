"""The request settings a service's config may change, and their defaults (the engine's, which
``fxis run`` checks a config against). A module of its own: the command line reads these
without importing the engine and NumPy with it."""

from __future__ import annotations

from typing import Any

REQUEST_DEFAULTS: dict[str, Any] = {
    "sync": "joint",
    "wait": "auto",
    "timeout_ms": 1000.0,
    "max_skew_ms": None,
    "horizon_ms": 10_000.0,
    "sync_tolerance_ms": 2.0,  # above cameras' jitter range, far below a frame period
    "max_pending": 1000,
    "max_pending_per_client": 100,
    "max_sequence_frames": 500,
}
