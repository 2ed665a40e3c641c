"""The dashboard's access to camera settings: read them and change them through a client of
its own, in a thread of its own (a change that restarts a camera's stream may take seconds:
the pictures and figures go on meanwhile)."""

from __future__ import annotations

import asyncio
from concurrent.futures import ThreadPoolExecutor

from fxis_shm.client.client import Client
from fxis_shm.wire.commands import SETTINGS_TIMEOUT_S
from fxis_shm.wire.security import ClientKeys


class CameraTuning:
    def __init__(self, endpoint: str | list[str], keys: ClientKeys | None = None):
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="dashboard-settings")
        self._endpoint, self._keys = endpoint, keys
        self._client: Client | None = None  # made in the pool's thread, on first use

    def _call(self, method: str, camera: str, **values) -> dict:
        if self._client is None:
            self._client = Client(self._endpoint, timeout=SETTINGS_TIMEOUT_S + 2, keys=self._keys)
        return getattr(self._client, method)(camera, **values)

    async def settings(self, camera: str) -> dict:
        return await asyncio.get_running_loop().run_in_executor(self._pool, lambda: self._call("settings", camera))

    async def configure(self, camera: str, values: dict) -> dict:
        return await asyncio.get_running_loop().run_in_executor(
            self._pool, lambda: self._call("configure", camera, **values)
        )

    def close(self) -> None:
        self._pool.submit(lambda: self._client.close() if self._client is not None else None)
        self._pool.shutdown(wait=True)
