"""The generic keys (trigger, pixel format, region, fps, exposure, gain, packet size) set
through Aravis' camera API, for the aravis backend (aravis.py).

A key that is not given leaves the camera as it is; a key the camera lacks or a value
outside what it allows raises the ValueError that ``refuse(key, value, allowed)`` makes,
before anything else is set. Aravis' own failures (GLib.Error) pass through.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from fxis_shm.service.camerakinds import ARAVIS_PIXEL_FORMATS

from .pixelformats import PIXEL_FORMATS as GENICAM_FORMATS

# The formats the aravis backend stores (a subset of the GenICam table).
PIXEL_FORMATS = {name: GENICAM_FORMATS[name] for name in ARAVIS_PIXEL_FORMATS}

Refuse = Callable[[str, Any, str], ValueError]


def apply_options(cam, options: Mapping[str, Any], refuse: Refuse, Aravis) -> None:
    """Set what ``options`` asks of the Aravis.Camera ``cam``, in an order the camera
    accepts: the trigger, the pixel format (it may change the allowed sizes), the
    region, then the numbers."""
    _set_trigger(cam, options["trigger"], refuse)
    if options["pixel_format"] is not None:
        _set_pixel_format(cam, options["pixel_format"], refuse)
    _set_region(cam, options, refuse)
    _set_numbers(cam, options, refuse, Aravis)


def _set_trigger(cam, trigger: str, refuse: Refuse) -> None:
    if trigger == "software":
        if not cam.is_software_trigger_supported():
            raise refuse("trigger", "software", "the camera has no TriggerSoftware command; use trigger=free")
        sources = list(cam.dup_available_trigger_sources() or [])
        if "Software" not in sources:
            raise refuse("trigger", "software", f"its TriggerSource offers {', '.join(sources) or 'nothing'}")
        cam.set_trigger("Software")  # TriggerSelector=FrameStart, TriggerMode=On, TriggerSource=Software
    elif cam.is_feature_available("TriggerMode"):
        cam.clear_triggers()  # TriggerMode=Off: free-running


def _set_pixel_format(cam, pixel_format: str, refuse: Refuse) -> None:
    offered = list(cam.dup_available_pixel_formats_as_strings())
    if pixel_format not in offered:
        usable = [f for f in offered if f in PIXEL_FORMATS]
        raise refuse(
            "pixel_format",
            pixel_format,
            f"it offers {', '.join(offered)}"
            + (f" (fxis stores {', '.join(usable) or 'none of them'})" if usable != offered else ""),
        )
    cam.set_pixel_format_from_string(pixel_format)


def _set_region(cam, o: Mapping[str, Any], refuse: Refuse) -> None:
    if all(o[k] is None for k in ("width", "height", "offset_x", "offset_y")):
        return
    x, y, w, h = cam.get_region()
    sized = o["width"] is not None or o["height"] is not None
    x = (0 if sized else x) if o["offset_x"] is None else o["offset_x"]  # a new size starts at 0,0
    y = (0 if sized else y) if o["offset_y"] is None else o["offset_y"]
    w = w if o["width"] is None else o["width"]
    h = h if o["height"] is None else o["height"]
    if cam.is_region_offset_available():
        cam.set_integer("OffsetX", 0)  # the largest width is allowed at offset 0
        cam.set_integer("OffsetY", 0)
    elif x or y:
        raise refuse("offset_x" if x else "offset_y", x or y, "the camera has no region offset")
    for key, value, bounds, step, offset, okey in (
        ("width", w, cam.get_width_bounds(), cam.get_width_increment(), x, "offset_x"),
        ("height", h, cam.get_height_bounds(), cam.get_height_increment(), y, "offset_y"),
    ):
        lo, hi = bounds
        if not lo <= value <= hi:
            raise refuse(key, value, f"it allows {lo}..{hi}" + (f" in steps of {step}" if step > 1 else ""))
        if step > 1 and (value - lo) % step:
            raise refuse(key, value, f"it allows {lo}..{hi} in steps of {step}")
        if offset + value > hi:
            raise refuse(okey, offset, f"with {key}={value} it allows at most {hi - value}")
    cam.set_integer("Width", w)
    cam.set_integer("Height", h)
    if x or y:
        for key, value, bounds in (
            ("offset_x", x, cam.get_x_offset_bounds()),
            ("offset_y", y, cam.get_y_offset_bounds()),
        ):
            if not bounds[0] <= value <= bounds[1]:
                raise refuse(key, value, f"it allows {bounds[0]}..{bounds[1]}")
        cam.set_integer("OffsetX", x)
        cam.set_integer("OffsetY", y)
    got = tuple(cam.get_region())
    if got != (x, y, w, h):
        raise refuse(
            "width/height/offset_x/offset_y", f"{w}x{h}+{x}+{y}", f"it set {got[2]}x{got[3]}+{got[0]}+{got[1]}"
        )


def _set_numbers(cam, o: Mapping[str, Any], refuse: Refuse, Aravis) -> None:
    # key, what the camera controls, is it there, its bounds, the unit, its auto mode (is it
    # there, switch it) and the setter: one row each, in this order
    for key, control, available, bounds, unit, auto, set_value in (
        ("fps", "frame rate", cam.is_frame_rate_available, cam.get_frame_rate_bounds, "", None, cam.set_frame_rate),
        (
            "exposure_us",
            "exposure time",
            cam.is_exposure_time_available,
            cam.get_exposure_time_bounds,
            " us",
            (cam.is_exposure_auto_available, cam.set_exposure_time_auto),
            cam.set_exposure_time,
        ),
        (
            "gain",
            "gain",
            cam.is_gain_available,
            cam.get_gain_bounds,
            "",
            (cam.is_gain_auto_available, cam.set_gain_auto),
            cam.set_gain,
        ),
    ):
        value = o[key]
        if value is None:
            continue
        if not available():
            raise refuse(key, value, f"the camera has no {control} control")
        lo, hi = bounds()
        if not lo <= value <= hi:
            raise refuse(key, value, f"it allows {lo:g}..{hi:g}{unit}")
        if auto is not None and auto[0]():
            auto[1](Aravis.Auto.OFF)  # an automatic mode would override the value
        set_value(value)
    if o["packet_size"] is not None:
        if not cam.is_gv_device():
            raise refuse("packet_size", o["packet_size"], "only GigE Vision cameras have one")
        lo, hi = cam.get_device().get_integer_feature_bounds("GevSCPSPacketSize")
        if not lo <= o["packet_size"] <= hi:
            raise refuse("packet_size", o["packet_size"], f"it allows {lo}..{hi} bytes")
        cam.gv_set_packet_size(o["packet_size"])
