"""The ``settings`` command, applied by the capture loop between two frames: read the camera's
settings, or change some, all or none.

Live keys are set on the running camera (and put back as they were if it refuses one);
keys that cost a restart (size, pixel format, region) restart the stream with the camera's
options plus every key asked for, so the new ring, its generation and the camera agree.
Every refusal names the limits; the camera keeps running on its old settings. A key asked for
with the value it has already is left alone (a request of only such keys costs ``UNCHANGED``:
nothing applied, no restart); a key that does not apply in the camera's mode (``fps`` on the
lockstep grid) is described read-only with the reason, so a change of it is refused with it.
"""

from __future__ import annotations

import json
import logging
import os
from typing import TYPE_CHECKING

from fxis_shm.core.tuning import LIVE, READ_ONLY, RESTART, UNCHANGED, check_change, cost_of
from fxis_shm.errors import ConfigError, SettingRefused
from fxis_shm.service.childspec import CameraWorkerSpec
from fxis_shm.shm import naming

if TYPE_CHECKING:
    from .camera import Stream

log = logging.getLogger("camera")


def handle(stream: Stream, command: dict) -> dict:
    """The answer to a ``settings`` command: the values, their limits, and for a change what
    each key took and what the change cost."""
    camera = stream.camera
    asked = command.get("set") or {}
    cost = None
    if asked:
        described = described_in_mode(stream, asked)
        split = check_change(camera.name, described, asked)
        for values in split.values():  # a key at the value it has: nothing to apply
            for key in [k for k, v in values.items() if described[k]["value"] == v]:
                del values[key]
        cost = cost_of(split)
        if cost == RESTART:
            _restart(stream, {**split[LIVE], **split[RESTART]})
        elif cost == LIVE:
            _live(stream, split[LIVE])
        camera = stream.camera
    described = described_in_mode(stream, asked)
    answer = {
        "values": {key: entry["value"] for key, entry in described.items()},
        "limits": {key: {k: v for k, v in entry.items() if k != "value"} for key, entry in described.items()},
        "generation": stream.ring.generation,
    }
    answer["ptp"] = _ptp(camera)
    if asked:
        answer.update(changed={key: described[key]["value"] for key in asked}, cost=cost)
        log.debug("camera %s: set %s (%s), took %s", camera.name, asked, cost, answer["changed"])
        if cost != UNCHANGED:
            remember(stream)
    if command.get("features"):
        answer["features"] = camera.features()
    return answer


def described_in_mode(stream: Stream, extra=()) -> dict:
    """The camera's settings as they apply in its mode: on the lockstep grid (a camera that
    can be triggered, in a service run with --lockstep) the grid sets the frame rate, so
    ``fps`` is read-only there, saying why."""
    described = stream.camera.settings(extra)
    grid = stream.timer.lockstep if stream.timer is not None and stream.camera.supports_trigger else None
    if grid is not None and "fps" in described:
        note = f"it does not apply on the lockstep grid, whose {grid[0]:g} Hz set the camera's rate (--lockstep)"
        described["fps"] = {**described["fps"], "access": READ_ONLY, "note": note}
    return described


def _ptp(camera) -> dict | None:
    """The camera's PTP state for status, read with its settings (at start, for each new
    generation, on each change); None for a camera that cannot say, or cannot now (lost)."""
    try:
        state = camera.ptp()
    except RuntimeError:  # not open: lost, being reopened
        return None
    return None if state is None else state.as_status()


# ---- kept while the service runs: a worker restarted after a crash starts with them ----


def _kept_path(spec: CameraWorkerSpec) -> str:
    return naming.state_path(spec.service, f"camera-{spec.camera}.settings")


def remembered(spec: CameraWorkerSpec) -> tuple[dict, dict]:
    """(options, node-map features by name) that changes made since the service started."""
    try:
        with open(_kept_path(spec)) as f:
            kept = json.load(f)
        return dict(kept["options"]), dict(kept["named"])
    except (OSError, ValueError, KeyError, TypeError):
        return {}, {}


def remember(stream: Stream) -> None:
    spec, options = stream.spec, stream.camera.options
    changed = {k: v for k, v in options.items() if spec.options.get(k) != v}
    path = _kept_path(spec)
    try:
        with open(path + ".tmp", "w") as f:
            json.dump({"options": {k: v for k, v in changed.items() if v is not None}, "named": stream.named}, f)
        os.chmod(path + ".tmp", 0o600)
        os.replace(path + ".tmp", path)
    except (OSError, TypeError) as exc:
        log.warning("camera %s: the change could not be kept for a restart of the worker: %s", spec.camera, exc)


def forget(spec: CameraWorkerSpec) -> None:
    try:
        os.unlink(_kept_path(spec))
    except OSError:
        pass


def _live(stream: Stream, values: dict) -> None:
    camera = stream.camera
    before = {key: entry["value"] for key, entry in camera.settings(values).items() if key in values}
    period = camera.nominal_period_ns
    try:
        camera.set_live(values)
    except Exception as exc:
        try:
            camera.set_live(before)
        except Exception:
            log.exception("camera %s: could not put back %s", camera.name, before)
        raise SettingRefused(f"camera {camera.name!r} refused {values}: {exc}; it keeps {before}") from None
    stream.named.update({key: value for key, value in values.items() if key not in camera.options})
    if camera.nominal_period_ns != period:  # a new rate: the wait policy and selection take it at once
        stream.ring.set_period(camera.nominal_period_ns)


def _restart(stream: Stream, values: dict) -> None:
    camera = stream.camera
    try:
        stream.restart({**camera.options, **values})
    except (ValueError, ConfigError) as exc:
        raise SettingRefused(f"camera {camera.name!r} cannot take {values}: {exc}; it keeps its settings") from None
    except Exception as exc:
        raise SettingRefused(
            f"camera {camera.name!r} failed to restart with {values} ({type(exc).__name__}: {exc}); "
            "it runs on its old settings"
        ) from None
    if stream.named:  # the features set by name before, on the new camera object
        try:
            stream.camera.set_live(stream.named)
        except Exception as exc:
            log.warning("camera %s: after the restart, %s could not be set again: %s", camera.name, stream.named, exc)
        if stream.camera.nominal_period_ns != stream.ring.field("nominal_period_ns"):
            stream.ring.set_period(stream.camera.nominal_period_ns)
