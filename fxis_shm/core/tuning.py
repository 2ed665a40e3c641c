"""Checking a request to change a camera's settings against what the camera says it allows.

Pure: a camera worker describes each setting it has as a dict (``value``, ``type``, ``access``,
``cost`` and its limits: ``min``/``max``/``inc`` for numbers, ``choices`` for enumerations),
and ``check_change`` takes that description and the values asked for, and returns them
typed and split by what applying them costs, or raises ``SettingRefused`` naming every
problem with the limits. Nothing is applied unless every value passes (all or none).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from fxis_shm.errors import SettingRefused

LIVE, RESTART = "live", "restart"  # applied between two frames / the stream restarts (new ring, generation + 1)
UNCHANGED = "none"  # a change's cost when every value asked for is the one the camera has: nothing applied
READ_WRITE, READ_ONLY = "rw", "ro"
TYPES = ("int", "float", "bool", "enum", "string")


def describe(
    value: Any,
    type_: str,
    cost: str = LIVE,
    access: str = READ_WRITE,
    *,
    lo: float | None = None,
    hi: float | None = None,
    inc: float | None = None,
    choices: list[str] | None = None,
    unit: str = "",
) -> dict[str, Any]:
    """One setting's description, as the wire carries it (the keys that apply, no others)."""
    entry: dict[str, Any] = {"value": value, "type": type_, "access": access, "cost": cost}
    for key, limit in (("min", lo), ("max", hi), ("inc", inc), ("choices", choices)):
        if limit is not None:
            entry[key] = limit
    if unit:
        entry["unit"] = unit
    return entry


def _number(value: float) -> str:
    return f"{value:.10g}"


def limits_text(entry: Mapping[str, Any]) -> str:
    """What a setting allows, in words: "1..49000 us", "in steps of 4", "one of mono8, bgr8"."""
    if entry.get("choices") is not None:
        return "one of " + ", ".join(map(str, entry["choices"]))
    if entry["type"] in ("int", "float"):
        lo, hi = entry.get("min"), entry.get("max")
        text = f"{'-inf' if lo is None else _number(lo)}..{'inf' if hi is None else _number(hi)}"
        if entry.get("inc") and entry["inc"] != 1:
            text += f" in steps of {_number(entry['inc'])}"
        return text + (f" {entry['unit']}" if entry.get("unit") else "")
    return f"a {entry['type']}"


def _typed(key: str, entry: Mapping[str, Any], value: Any) -> Any:
    """``value`` as the setting's type, or ValueError saying why not."""
    kind = entry["type"]
    if kind == "bool":
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false", "on", "off", "1", "0"):
            return value.lower() in ("true", "on", "1")
        raise ValueError(f"{key} must be true or false, got {value!r}")
    if kind in ("int", "float"):
        if isinstance(value, bool):
            raise ValueError(f"{key} must be a number, got {value!r}")
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{key} must be a number, got {value!r}") from None
        if not math.isfinite(number):
            raise ValueError(f"{key} must be a finite number, got {value!r}")
        lo, hi = entry.get("min"), entry.get("max")
        if (lo is not None and number < lo) or (hi is not None and number > hi):
            raise ValueError(f"{key}={_number(number)} is out of range: it allows {limits_text(entry)}")
        if kind == "float":
            return number
        inc = entry.get("inc") or 1
        base = lo if lo is not None else 0
        stepped = base + round((number - base) / inc) * inc  # the camera would round it so
        if hi is not None and stepped > hi:
            stepped -= inc
        return int(stepped)
    text = str(value)
    choices = entry.get("choices")
    if choices is not None and text not in choices:
        raise ValueError(f"{key}={text!r} is not {limits_text(entry)}")
    return text


def check_change(
    camera: str, described: Mapping[str, Mapping[str, Any]], values: Mapping[str, Any]
) -> dict[str, dict[str, Any]]:
    """The values asked for, typed (integers rounded to their step), keyed by cost:
    ``{"live": {...}, "restart": {...}}``. SettingRefused names every key that is unknown,
    read-only or out of its limits; then nothing may be applied."""
    if not values:
        raise SettingRefused(f"no setting to change on camera {camera!r}: give KEY=VALUE pairs")
    problems: list[str] = []
    split: dict[str, dict[str, Any]] = {LIVE: {}, RESTART: {}}
    for key, value in values.items():
        entry = described.get(key)
        if entry is None:
            known = ", ".join(sorted(described)) or "none"
            problems.append(f"camera {camera!r} has no setting {key!r} (it has: {known})")
        elif entry["access"] != READ_WRITE:
            note = f": {entry['note']}" if entry.get("note") else ""
            now = "" if entry["value"] is None else f" (now {entry['value']!r})"
            problems.append(f"{key} of camera {camera!r} is read-only{now}{note}")
        else:
            try:
                split[entry["cost"]][key] = _typed(key, entry, value)
            except ValueError as exc:
                problems.append(str(exc))
    if problems:
        raise SettingRefused("; ".join(problems) + f"; camera {camera!r} keeps its settings")
    return split


def cost_of(split: Mapping[str, Mapping[str, Any]]) -> str:
    """What applying a checked change costs: a restart of the stream if any key needs one,
    nothing if no key is left to apply."""
    return RESTART if split[RESTART] else LIVE if split[LIVE] else UNCHANGED
