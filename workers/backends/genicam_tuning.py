"""Run-time settings of a GenTL camera (genicam.py), for the worker's settings command: the
generic keys through the device's SFNC features, and any feature of its node map by name,
described from its node (type, access, range or enumeration, value).

Exposure, gain, frame rate and node-map features are live; size, region and pixel format
restart the stream. Features that shape the stream or the acquisition are read-only by name.
A key the device lacks (viky.cti has no ExposureTime or Gain) is not listed, so asking for
it is refused naming what the device has.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from fxis_shm.core.tuning import READ_ONLY, RESTART, describe

from .genicam_features import DeviceFeatures, short_error
from .pixelformats import PIXEL_FORMATS

# generic key: (the SFNC features that carry it, first found wins; cost)
GENERIC = {
    "exposure_us": (("ExposureTime", "ExposureTimeAbs"), "live"),
    "gain": (("Gain", "GainRaw"), "live"),
    "fps": (("AcquisitionFrameRate", "AcquisitionFrameRateAbs"), "live"),
    "width": (("Width",), RESTART),
    "height": (("Height",), RESTART),
    "offset_x": (("OffsetX",), RESTART),
    "offset_y": (("OffsetY",), RESTART),
    "pixel_format": (("PixelFormat",), RESTART),
}
BY_KEY = {name: key for key, (names, _) in GENERIC.items() for name in names}
FIXED = {"TriggerMode", "TriggerSource", "TriggerSelector", "AcquisitionMode", "TLParamsLocked"}
_AUTO = {"exposure_us": "ExposureAuto", "gain": "GainAuto"}


def _type(node, genapi) -> str | None:
    kinds = genapi.EInterfaceType
    return {
        kinds.intfIInteger: "int",
        kinds.intfIFloat: "float",
        kinds.intfIBoolean: "bool",
        kinds.intfIEnumeration: "enum",
        kinds.intfIString: "string",
        kinds.intfICommand: "command",
    }.get(node.node.principal_interface_type)


def _describe_node(features: DeviceFeatures, node, genapi, cost: str = "live") -> dict | None:
    type_ = _type(node, genapi)
    if type_ is None:
        return None
    value: Any = None
    limits: dict[str, Any] = {}
    try:
        if features.readable(node.node) and type_ != "command":
            value = node.value
        if type_ in ("int", "float"):
            limits = dict(lo=node.min, hi=node.max)
            if type_ == "int":
                limits["inc"] = node.inc
            elif getattr(node, "unit", ""):
                limits["unit"] = node.unit
        elif type_ == "enum":
            limits = dict(choices=[e.symbolic for e in node.entries if features.available(e.node)])
    except Exception:  # limits the node map does not give now
        limits = {}
    access = "rw" if features.writable(node.node) and features.readable(node.node) else READ_ONLY
    return describe(value, type_, cost, access, **limits)


def generic(features: DeviceFeatures, genapi) -> dict[str, dict]:
    out = {}
    for key, (names, cost) in GENERIC.items():
        node = features.node(*names)
        if node is not None and (described := _describe_node(features, node, genapi, cost)) is not None:
            if key == "pixel_format":
                described["choices"] = [c for c in described.get("choices", []) if c in PIXEL_FORMATS]
            out[key] = described
    return out


def feature(features: DeviceFeatures, name: str, genapi) -> dict | None:
    node = features.node(name)
    described = _describe_node(features, node, genapi) if node is not None else None
    if described is not None and (name in BY_KEY or name in FIXED or described["type"] == "command"):
        described["access"] = READ_ONLY
        if name in BY_KEY:
            described["note"] = f"set it as {BY_KEY[name]}"
    return described


def describe_all(features: DeviceFeatures, trigger: str, extra: Iterable[str], genapi) -> dict[str, dict]:
    out = generic(features, genapi)
    if features.node("TriggerSoftware") is not None and features.node("TriggerMode") is not None:
        out["trigger"] = describe(trigger, "enum", RESTART, choices=["free", "software"])
    else:
        out["trigger"] = describe(trigger, "enum", RESTART, READ_ONLY)
        out["trigger"]["note"] = "the device has no TriggerSoftware and TriggerMode"
    for name in extra:
        if name not in out and (found := feature(features, name, genapi)) is not None:
            out[name] = found
    return out


def set_live(features: DeviceFeatures, values: Mapping[str, Any]) -> None:
    for key, value in values.items():
        if key in _AUTO:
            features.switch_off(_AUTO[key])
        names = GENERIC[key][0] if key in GENERIC else (key,)
        node = features.node(*names)
        try:
            node.value = value
        except Exception as exc:  # GenApi exceptions: the device refused
            raise ValueError(f"the device refused {key}={value!r}: {short_error(exc)}") from None


def features_of(features: DeviceFeatures, genapi) -> list[dict]:
    """Every feature under the node map's Root category, in its order."""
    found = []

    def walk(node) -> None:
        if node.node.principal_interface_type == genapi.EInterfaceType.intfICategory:
            for child in node.features:
                walk(child)
        elif (described := feature(features, node.node.name, genapi)) is not None:
            found.append({"name": node.node.name, **described})

    walk(features.node_map.get_node("Root"))
    return found
