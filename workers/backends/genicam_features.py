"""The generic keys (pixel format, region, exposure, gain, fps, trigger) set through a
GenICam device's SFNC features, for the genicam backend (genicam.py).

A feature is used when the device implements it and makes it available now; a key
the device lacks or a value it refuses raises a ValueError naming the camera, the key
and what the device allows.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fxis_shm.shm.ring import FrameLayout

from .genicam_timing import period_ns
from .pixelformats import PIXEL_FORMATS, image_layout


def refusal(camera: str, key: str | None, why: str) -> ValueError:
    return ValueError(f"camera {camera!r}: key {key!r}: {why}")


def short_error(exc: Exception) -> str:
    """GenICam exception texts carry file and line; keep their first sentence."""
    message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return message[:200]


class DeviceFeatures:
    """The features of one device's node map (``genapi`` is genicam.genapi), set by key."""

    def __init__(self, node_map, genapi, camera: str):
        self._node_map, self._genapi, self.camera = node_map, genapi, camera

    def _refuse(self, key: str | None, why: str) -> ValueError:
        return refusal(self.camera, key, why)

    @property
    def node_map(self):
        return self._node_map

    def available(self, node) -> bool:
        return self._available(node)

    def _available(self, node) -> bool:
        return node.get_access_mode() not in (self._genapi.EAccessMode.NI, self._genapi.EAccessMode.NA)

    def readable(self, node) -> bool:
        return node.get_access_mode() in (self._genapi.EAccessMode.RO, self._genapi.EAccessMode.RW)

    def writable(self, node) -> bool:
        return node.get_access_mode() in (self._genapi.EAccessMode.WO, self._genapi.EAccessMode.RW)

    def node(self, *names):
        """The first of ``names`` the device implements and makes available now, or None."""
        for name in names:
            try:
                node = getattr(self._node_map, name)
            except AttributeError:
                continue
            if self._available(node):
                return node
        return None

    def set_enum(self, key: str | None, node, value: str, quiet: bool = False) -> str:
        """Set an enumeration by its symbolic name (case-insensitive); returns the name set
        ('' if ``quiet`` and the device would not)."""
        offered = [e.symbolic for e in node.entries if self._available(e.node)]
        match = next((s for s in offered if s.lower() == value.lower()), None)
        if match is not None and self.readable(node.node) and node.value == match:
            return match  # already so, whether or not it could change now
        if match is None or not self.writable(node.node):
            if quiet:
                return ""
            if match is None:
                raise self._refuse(
                    key, f"the device does not offer {value!r}; it offers {', '.join(offered) or 'nothing'}"
                )
            raise self._refuse(key, f"the device does not let {node.node.name} change now")
        try:
            node.value = match
        except Exception as exc:  # GenApi exceptions: the device refused
            if quiet:
                return ""
            raise self._refuse(key, f"the device refused {match!r}: {short_error(exc)}") from None
        return match

    def set_number(self, key: str, names: tuple[str, ...], value: float, integer: bool) -> None:
        node = self.node(*names)
        if node is None:
            raise self._refuse(key, f"the device has no {' or '.join(names)} feature")
        if not self.writable(node.node):
            raise self._refuse(key, f"the device does not let {node.node.name} change now")
        if integer:
            value = int(round(value))
        lo, hi = node.min, node.max
        step = ""
        if integer:
            inc = node.inc
            step = f" in steps of {inc}" if inc > 1 else ""
            if inc > 1 and (value - lo) % inc:
                raise self._refuse(key, f"{value} is not allowed; the device allows {lo}..{hi}{step}")
        if not lo <= value <= hi:
            raise self._refuse(key, f"{value:g} is out of range; the device allows {lo:g}..{hi:g}{step}")
        try:
            node.value = value
        except Exception as exc:  # GenApi exceptions: the device refused
            raise self._refuse(key, f"the device refused {value:g}: {short_error(exc)}") from None

    def switch_off(self, *names: str) -> None:
        """Turn an automatic mode (ExposureAuto, GainAuto) off if the device has it."""
        node = self.node(*names)
        if node is not None:
            self.set_enum(None, node, "Off", quiet=True)

    # -- the generic keys ------------------------------------------------------------

    def configure(self, o: Mapping[str, Any]) -> tuple[str, FrameLayout]:
        """Set the keys ``o`` gives; (the pixel format, the layout of the images) as set."""
        pixel_format = self._set_pixel_format(o["pixel_format"])
        for size, offset, axis in (("width", "offset_x", "OffsetX"), ("height", "offset_y", "OffsetY")):
            if o[size] is None and o[offset] is None:
                continue
            node = self.node(axis)
            if node is not None and self.writable(node.node) and node.value != node.min:
                try:
                    node.value = node.min  # room for the largest size first
                except Exception as exc:  # GenApi exceptions: the device refused
                    raise self._refuse(
                        offset, f"the device refused to move {axis} to {node.min}: {short_error(exc)}"
                    ) from None
            if o[size] is not None:
                self.set_number(size, (size.capitalize(),), o[size], integer=True)
            if o[offset] is not None:
                self.set_number(offset, (axis,), o[offset], integer=True)
        if o["exposure_us"] is not None:
            self.switch_off("ExposureAuto")
            self.set_number("exposure_us", ("ExposureTime", "ExposureTimeAbs"), o["exposure_us"], False)
        if o["gain"] is not None:
            self.switch_off("GainAuto")
            gain = self.node("Gain", "GainRaw")
            integer = gain is not None and gain.node.name == "GainRaw"
            self.set_number("gain", ("Gain", "GainRaw"), o["gain"], integer)
        if o["fps"] is not None:
            enable = self.node("AcquisitionFrameRateEnable", "AcquisitionFrameRateEnabled")
            if enable is not None and self.writable(enable.node):
                enable.value = True
            self.set_number("fps", ("AcquisitionFrameRate", "AcquisitionFrameRateAbs"), o["fps"], False)
        self._set_trigger(o["trigger"] == "software")
        width, height = self.node("Width"), self.node("Height")
        if width is None or height is None:
            raise ValueError(
                f"camera {self.camera!r}: the device has no Width/Height features; fxis cannot tell its image size"
            )
        return pixel_format, image_layout(pixel_format, width.value, height.value, o["raw"])

    def _set_pixel_format(self, wanted: str | None) -> str:
        node = self.node("PixelFormat")
        if wanted:
            if node is None:
                raise self._refuse("pixel_format", "the device has no PixelFormat feature")
            self.set_enum("pixel_format", node, wanted)
        if node is None or not self.readable(node.node):
            raise ValueError(
                f"camera {self.camera!r}: the device does not say its PixelFormat; "
                f"fxis cannot tell how to read its images"
            )
        pixel_format = node.value
        if pixel_format not in PIXEL_FORMATS:
            offered = [e.symbolic for e in node.entries if e.symbolic in PIXEL_FORMATS and self._available(e.node)]
            raise self._refuse(
                "pixel_format",
                f"fxis cannot convert {pixel_format!r} to NumPy; "
                f"set one the device offers that it can: "
                f"{', '.join(offered) or 'none'}",
            )
        return pixel_format

    def _set_trigger(self, software: bool) -> None:
        mode = self.node("TriggerMode")
        selector = self.node("TriggerSelector")
        if software:
            if self.node("TriggerSoftware") is None or mode is None or self.node("TriggerSource") is None:
                raise self._refuse(
                    "trigger",
                    "software triggering needs the device's TriggerMode, "
                    "TriggerSource and TriggerSoftware features, which it "
                    "lacks; it allows trigger=free only",
                )
            if selector is not None:
                for name in ("FrameStart", "AcquisitionStart"):
                    if self.set_enum(None, selector, name, quiet=True):
                        break
            self.set_enum("trigger", self.node("TriggerSource"), "Software")
            self.set_enum("trigger", mode, "On")
        elif mode is not None:  # a device left in trigger mode would never stream freely
            if selector is not None:
                self.set_enum(None, selector, "FrameStart", quiet=True)
            self.set_enum(None, mode, "Off", quiet=True)

    def frame_period_ns(self) -> int:
        """The period of the frame rate the device says it runs at, 0 if it does not say."""
        node = self.node(
            "ResultingFrameRate", "AcquisitionResultingFrameRate", "AcquisitionFrameRate", "AcquisitionFrameRateAbs"
        )
        try:
            fps = float(node.value) if node is not None and self.readable(node.node) else 0.0
        except Exception:  # some devices compute it only while acquiring
            fps = 0.0
        return period_ns(fps)
