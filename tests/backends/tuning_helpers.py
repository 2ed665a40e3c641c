"""Reading a camera's frames and its refusals around a change of its settings, for the tests
of settings at run time against real cameras (test_aravis.py, test_tuning_backends.py)."""

import pytest

from fxis_shm.errors import ServiceError, SettingRejected

from ..conftest import wait_until


def latest_of(client, camera: str, generation: int | None = None):
    """The newest frame of ``camera`` (of ``generation``), None while there is none (a ring just
    made for a new size holds no frame yet)."""
    try:
        frame = client.latest([camera])[camera]
    except ServiceError as exc:
        if exc.code != "NO_FRAMES":
            raise
        return None
    return frame if generation is None or frame.generation == generation else None


def newest_after(client, camera: str, after=None):
    """The newest frame of ``camera`` once one newer than ``after`` (a frame) is stored."""

    def newer():
        frame = latest_of(client, camera)
        return frame if frame is not None and (after is None or frame.t_capture > after.t_capture) else None

    return wait_until(newer, what=f"a newer frame of {camera}")


def refusal(client, camera: str, **values) -> str:
    with pytest.raises(SettingRejected) as refused:
        client.configure(camera, **values)
    return refused.value.message
