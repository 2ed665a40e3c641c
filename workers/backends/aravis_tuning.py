"""Run-time settings of an Aravis camera (aravis.py), for the worker's settings command: the
generic keys through Aravis' camera API, and any feature of the camera's node map by its
SFNC name (``ExposureTimeAbs``, ``GainRaw``, ``TestRegister``, ...), described from its
GenICam node: type, access, range or enumeration, value (what ``arv-tool features`` shows).

Exposure, gain, frame rate and node-map features are live; size, region and pixel format
restart the stream (the worker opens the camera again with them). Features that shape the
stream (Width, PixelFormat, the trigger, ...) are read-only by name: they have generic keys
or are set at start-up.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from fxis_shm.core.tuning import READ_ONLY, RESTART, describe

from .aravis_settings import PIXEL_FORMATS

# Features the stream's layout or acquisition depends on: changed through the generic keys
# (a restart of the stream) or at start-up, never by name.
BY_KEY = {
    "Width": "width",
    "Height": "height",
    "OffsetX": "offset_x",
    "OffsetY": "offset_y",
    "PixelFormat": "pixel_format",
}
FIXED = {"TriggerMode", "TriggerSource", "TriggerSelector", "AcquisitionMode", "AcquisitionStart", "AcquisitionStop"}
_KINDS = ("GcEnumeration", "GcBoolean", "GcCommand", "GcFloat", "GcInteger", "GcString")  # most specific first
_TYPES = {"GcEnumeration": "enum", "GcBoolean": "bool", "GcCommand": "command", "GcFloat": "float"}


def generic(cam, trigger: str) -> dict[str, dict]:
    """The generic keys the camera has, described (``trigger``: its trigger option now)."""
    out: dict[str, dict] = {}
    if cam.is_exposure_time_available():
        lo, hi = cam.get_exposure_time_bounds()
        out["exposure_us"] = describe(cam.get_exposure_time(), "float", lo=lo, hi=hi, unit="us")
    if cam.is_gain_available():
        lo, hi = cam.get_gain_bounds()
        out["gain"] = describe(cam.get_gain(), "float", lo=lo, hi=hi)
    if cam.is_frame_rate_available():
        lo, hi = cam.get_frame_rate_bounds()
        out["fps"] = describe(cam.get_frame_rate(), "float", lo=lo, hi=hi)
    x, y, w, h = cam.get_region()
    for key, value, bounds, inc in (
        ("width", w, cam.get_width_bounds(), cam.get_width_increment()),
        ("height", h, cam.get_height_bounds(), cam.get_height_increment()),
    ):
        out[key] = describe(value, "int", RESTART, lo=bounds[0], hi=bounds[1], inc=inc)
    if cam.is_region_offset_available():
        for key, value, bounds in (
            ("offset_x", x, cam.get_x_offset_bounds()),
            ("offset_y", y, cam.get_y_offset_bounds()),
        ):
            out[key] = describe(value, "int", RESTART, lo=bounds[0], hi=bounds[1])
    offered = [f for f in cam.dup_available_pixel_formats_as_strings() if f in PIXEL_FORMATS]
    out["pixel_format"] = describe(cam.get_pixel_format_as_string(), "enum", RESTART, choices=offered)
    if cam.is_software_trigger_supported():
        out["trigger"] = describe(trigger, "enum", RESTART, choices=["free", "software"])
    else:
        out["trigger"] = describe(trigger, "enum", RESTART, READ_ONLY)
        out["trigger"]["note"] = "the camera has no TriggerSoftware command"
    return out


def _kind(node, Aravis) -> str | None:
    return next((k for k in _KINDS if isinstance(node, getattr(Aravis, k))), None)


def feature(cam, name: str, Aravis) -> dict | None:
    """The node-map feature ``name`` described (None if the camera has none of that name)."""
    node = cam.get_device().get_genicam().get_node(name)
    kind = _kind(node, Aravis) if node is not None else None
    if kind is None or not node.is_implemented():
        return None
    access = node.get_actual_access_mode().value_nick if node.is_available() else "na"
    type_ = _TYPES.get(kind, "int" if kind == "GcInteger" else "string")
    limits: dict[str, Any] = {}
    value: Any = None
    try:
        if type_ == "int":
            value = Aravis.GcInteger.get_value(node)
            limits = dict(lo=Aravis.GcInteger.get_min(node), hi=Aravis.GcInteger.get_max(node))
            limits["inc"] = Aravis.GcInteger.get_inc(node)
        elif type_ == "float":
            value = Aravis.GcFloat.get_value(node)
            limits = dict(lo=Aravis.GcFloat.get_min(node), hi=Aravis.GcFloat.get_max(node))
            limits["unit"] = Aravis.GcFloat.get_unit(node) or ""
        elif type_ == "enum":
            value, limits = node.get_string_value(), dict(choices=list(node.dup_available_string_values()))
        elif type_ == "bool":
            value = node.get_value()
        elif type_ == "string":
            value = node.get_value_as_string()
    except Exception:  # a feature whose limits the node map does not give (a SwissKnife, say)
        limits = {}
    if access != "rw" or type_ == "command" or name in BY_KEY or name in FIXED:
        access = READ_ONLY
    described = describe(value, type_, access=access, **limits)
    if name in BY_KEY:
        described["note"] = f"set it as {BY_KEY[name]} (a restart of the stream)"
    return described


def describe_all(cam, trigger: str, extra: Iterable[str], Aravis) -> dict[str, dict]:
    """The generic keys, plus the node-map features named in ``extra`` that the camera has."""
    out = generic(cam, trigger)
    for name in extra:
        if name not in out and (found := feature(cam, name, Aravis)) is not None:
            out[name] = found
    return out


def set_live(cam, values: Mapping[str, Any], Aravis) -> None:
    """Apply checked live keys and features, in the order asked."""
    device = cam.get_device()
    for key, value in values.items():
        if key == "exposure_us":
            if cam.is_exposure_auto_available():
                cam.set_exposure_time_auto(Aravis.Auto.OFF)
            cam.set_exposure_time(value)
        elif key == "gain":
            if cam.is_gain_auto_available():
                cam.set_gain_auto(Aravis.Auto.OFF)
            cam.set_gain(value)
        elif key == "fps":
            cam.set_frame_rate(value)
        else:
            setter = {
                bool: device.set_boolean_feature_value,
                int: device.set_integer_feature_value,
                float: device.set_float_feature_value,
            }.get(type(value), device.set_string_feature_value)
            setter(key, value)


def features(cam, Aravis) -> list[dict]:
    """Every feature under the node map's Root category, in its order."""
    genicam, found = cam.get_device().get_genicam(), []

    def walk(name: str) -> None:
        node = genicam.get_node(name)
        if isinstance(node, Aravis.GcCategory):
            for child in node.get_features():
                walk(child)
        elif (described := feature(cam, name, Aravis)) is not None:
            found.append({"name": name, **described})

    walk("Root")
    return found
