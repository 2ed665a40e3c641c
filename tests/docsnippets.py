"""Fixtures for the Python snippets of README.md and docs/ (pytest-markdown-docs runs every
```python block there as a test; ``--markdown-docs`` in pyproject.toml). A block names what it
needs in its info string, e.g. ```` ```python fixture:fxis_service ````; a block that cannot run
here (other hosts, keys of a real cell) says ``notest`` and, in its first line, why.

``fxis_service`` is what the README's quick start assumes: ``fxis run`` with its defaults
(two synthetic cameras, requests on tcp://127.0.0.1:5555, streams on 5556, events on 5557),
started once for all snippets.
"""

from __future__ import annotations

import os

import pytest

from fxis_shm.service.launch import ServiceProcess
from fxis_shm.wire import defaults

from .conftest import wait_until


@pytest.fixture(scope="session")
def fxis_service():
    svc = ServiceProcess(
        ["--camera", "cam0=synthetic:width=640,height=480", "--camera", "cam1=synthetic:width=640,height=480"],
        endpoint=defaults.ENDPOINT,
        pub=defaults.PUB,
        events=defaults.EVENTS,
        stderr=open(os.devnull, "w"),
    )
    svc.start()
    with svc.client() as client:  # a second of history, as a service that has run a while has
        wait_until(
            lambda: all(c["frames_stored"] >= c["ring_slots"] for c in client.status()["cameras"].values()),
            what="full rings",
        )
    yield svc
    svc.stop()
