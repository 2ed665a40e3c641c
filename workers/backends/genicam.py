"""GenICam cameras through any vendor's GenTL producer (``harvesters``).

A GenTL producer is a shared library with a ``.cti`` suffix that a camera
vendor ships (Basler pylon, Allied Vision Vimba X, Teledyne, ...); the
``genicam`` wheel ships ``viky.cti``, a simulated producer with three devices.
``cti=`` names the producer (a file, or a folder of them); without it the
producers are those of the standard GenTL environment variable
``GENICAM_GENTL64_PATH``: a path list (``:``-separated) of folders holding
``.cti`` files.

The generic keys (fps, width, height, offsets, pixel format, exposure, gain,
trigger) are set through the device's SFNC features when the device offers
them; a key the device lacks or a value it refuses stops start-up with a
ValueError that names the camera, the key and what the device allows.

Images (workers/backends/pixelformats.py): the buffer's component is converted to NumPy and copied out before the
buffer goes back to the producer. Mono8 -> (h, w) uint8; Mono10..16 -> (h, w)
uint16 as delivered; RGB8/RGBa8/BGRa8 -> BGR; Bayer -> BGR (cv2 demosaicing);
``raw=true`` keeps colour and Bayer data as delivered.

Timestamps (``timestamp=``): ``host`` is CLOCK_MONOTONIC when the buffer was
fetched; ``device`` maps the buffer's device timestamp onto CLOCK_MONOTONIC with
``DeviceClockFit`` (capture time on the camera's clock, so transfer jitter
drops out; the device must timestamp its buffers, which start-up checks).
"""

from __future__ import annotations

import glob
import logging
import os
import time

from fxis_shm.core import timebase
from fxis_shm.core.clocks import DeviceClockFit, PtpClock
from fxis_shm.service.camerakinds import GENTL_PATH_VAR
from fxis_shm.shm.ring import FrameLayout

from .base import Camera, CameraLost, Capture
from .pixelformats import PIXEL_FORMATS, image_layout, to_image

log = logging.getLogger("camera")

_INSTALL_HINT = "the genicam backend needs harvesters and genicam: pip install 'fxis-shm[genicam]'"
_PROBE_AFTER_S = 1.0  # without frames this long, check that the device still answers
_FIRST_FRAME_S = 5.0  # how long start-up waits for a frame when it must look at one
_EVENT_WAIT_MS = 5


def _sdk():
    """harvesters.core, genicam.genapi and genicam.gentl, or ImportError saying what to install."""
    try:
        from genicam import genapi, gentl
        from harvesters import core
    except ImportError as exc:
        raise ImportError(f"{_INSTALL_HINT} ({exc})") from exc
    return core, genapi, gentl


def _harvester(core):
    """A Harvester logging through ours: harvesters logs every buffer event at INFO,
    so only its errors are kept."""
    logger = logging.getLogger("camera.harvesters")
    logger.setLevel(logging.ERROR)
    return core.Harvester(config=core.ParameterSet({core.ParameterKey.LOGGER: logger}))


def producers_in(path: str) -> list[str]:
    """The .cti files a path names: the file itself, or those in a folder."""
    if os.path.isdir(path):
        return sorted(glob.glob(os.path.join(path, "*.cti")))
    return [path] if os.path.isfile(path) else []


def producers_from_env(environ=os.environ) -> list[str]:
    """The producers of GENICAM_GENTL64_PATH (folders holding .cti files), in its order."""
    files: list[str] = []
    for folder in environ.get(GENTL_PATH_VAR, "").split(os.pathsep):
        for cti in producers_in(folder) if folder else []:
            if cti not in files:
                files.append(cti)
    return files


def _readable(node, genapi) -> bool:
    return node.get_access_mode() in (genapi.EAccessMode.RO, genapi.EAccessMode.RW)


def _writable(node, genapi) -> bool:
    return node.get_access_mode() in (genapi.EAccessMode.WO, genapi.EAccessMode.RW)


def _short(exc: Exception) -> str:
    """GenICam exception texts carry file and line; keep their first sentence."""
    message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return message[:200]


class GenicamCamera(Camera):
    kind = "genicam"

    def __init__(self, name, options, time_origin_ns):
        super().__init__(name, options, time_origin_ns)
        self.note = ""
        self._harvester = None
        self._ia = None
        self._layout: FrameLayout | None = None
        self._period_ns = 0
        self._k = -1  # the last frame index handed out; continues across reopenings
        self._last_device_id: int | None = None
        self._incomplete = 0
        self._fit: DeviceClockFit | PtpClock | None = None
        self._device_ns = True  # the buffers' timestamps are in ns (else in ticks)
        self._last_frame_s = 0.0
        self._pixel_format = ""

    # -- configuration ---------------------------------------------------------------

    def _refuse(self, key: str, why: str) -> ValueError:
        return ValueError(f"camera {self.name!r}: key {key!r}: {why}")

    def _producers(self) -> list[str]:
        cti = self.options["cti"]
        if cti:
            files = producers_in(cti)
            if not files:
                what = "folder holds no .cti file" if os.path.isdir(cti) else "file does not exist"
                raise self._refuse("cti", f"{cti!r}: the {what}; give a GenTL producer (.cti) or a folder holding one")
            return files
        files = producers_from_env()
        if not files:
            raise self._refuse(
                "cti",
                f"no producer given and ${GENTL_PATH_VAR} "
                f"({os.environ.get(GENTL_PATH_VAR, 'not set')!r}) names no folder "
                f"holding a .cti file; set cti=/path/to/producer.cti",
            )
        return files

    def _pick_device(self, infos: list, files: list[str]) -> int:
        """Index into the device list of the device option."""
        want = self.options["device"]
        if not infos:
            raise self._refuse("device", f"the producer(s) {', '.join(files)} list no device")
        if want is None:
            return 0
        for i, info in enumerate(infos):
            if want in (_prop(info, "serial_number"), _prop(info, "id_"), _prop(info, "user_defined_name")):
                return i
        if want.isdigit() and int(want) < len(infos):
            return int(want)
        listing = "; ".join(
            f"{i}: {_prop(info, 'serial_number') or '-'} ({_prop(info, 'id_')}, {_prop(info, 'model')})"
            for i, info in enumerate(infos)
        )
        raise self._refuse("device", f"no device {want!r}; the producer(s) offer (index: serial (id, model)) {listing}")

    def _node(self, *names):
        """The first of ``names`` the device implements and makes available now, or None."""
        _, genapi, _ = _sdk()
        nm = self._ia.remote_device.node_map
        for name in names:
            try:
                node = getattr(nm, name)
            except AttributeError:
                continue
            if node.get_access_mode() not in (genapi.EAccessMode.NI, genapi.EAccessMode.NA):
                return node
        return None

    def _set_enum(self, key: str | None, node, value: str, quiet: bool = False) -> str:
        """Set an enumeration by its symbolic name (case-insensitive); returns the name set."""
        _, genapi, _ = _sdk()
        offered = [
            e.symbolic
            for e in node.entries
            if e.node.get_access_mode() not in (genapi.EAccessMode.NI, genapi.EAccessMode.NA)
        ]
        match = next((s for s in offered if s.lower() == value.lower()), None)
        if match is not None and _readable(node.node, genapi) and node.value == match:
            return match  # already so, whether or not it could change now
        if match is None or not _writable(node.node, genapi):
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
            raise self._refuse(key, f"the device refused {match!r}: {_short(exc)}") from None
        return match

    def _set_number(self, key: str, names: tuple[str, ...], value: float, integer: bool) -> None:
        _, genapi, _ = _sdk()
        node = self._node(*names)
        if node is None:
            raise self._refuse(key, f"the device has no {' or '.join(names)} feature")
        if not _writable(node.node, genapi):
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
            raise self._refuse(key, f"the device refused {value:g}: {_short(exc)}") from None

    def _switch_off(self, *names: str) -> None:
        """Turn an automatic mode (ExposureAuto, GainAuto) off if the device has it."""
        node = self._node(*names)
        if node is not None:
            self._set_enum(None, node, "Off", quiet=True)

    def _configure(self) -> None:
        o = self.options
        _, genapi, _ = _sdk()
        node = self._node("PixelFormat")
        if o["pixel_format"]:
            if node is None:
                raise self._refuse("pixel_format", "the device has no PixelFormat feature")
            self._set_enum("pixel_format", node, o["pixel_format"])
        if node is None or not _readable(node.node, genapi):
            raise ValueError(
                f"camera {self.name!r}: the device does not say its PixelFormat; "
                f"fxis cannot tell how to read its images"
            )
        self._pixel_format = node.value
        if self._pixel_format not in PIXEL_FORMATS:
            offered = [
                e.symbolic
                for e in node.entries
                if e.symbolic in PIXEL_FORMATS
                and e.node.get_access_mode() not in (genapi.EAccessMode.NI, genapi.EAccessMode.NA)
            ]
            raise self._refuse(
                "pixel_format",
                f"fxis cannot convert {self._pixel_format!r} to NumPy; "
                f"set one the device offers that it can: "
                f"{', '.join(offered) or 'none'}",
            )
        for size, offset, axis in (("width", "offset_x", "OffsetX"), ("height", "offset_y", "OffsetY")):
            if o[size] is None and o[offset] is None:
                continue
            node = self._node(axis)
            if node is not None and _writable(node.node, genapi) and node.value != node.min:
                try:
                    node.value = node.min  # room for the largest size first
                except Exception as exc:  # GenApi exceptions: the device refused
                    raise self._refuse(
                        offset, f"the device refused to move {axis} to {node.min}: {_short(exc)}"
                    ) from None
            if o[size] is not None:
                self._set_number(size, (size.capitalize(),), o[size], integer=True)
            if o[offset] is not None:
                self._set_number(offset, (axis,), o[offset], integer=True)
        if o["exposure_us"] is not None:
            self._switch_off("ExposureAuto")
            self._set_number("exposure_us", ("ExposureTime", "ExposureTimeAbs"), o["exposure_us"], False)
        if o["gain"] is not None:
            self._switch_off("GainAuto")
            gain = self._node("Gain", "GainRaw")
            integer = gain is not None and gain.node.name == "GainRaw"
            self._set_number("gain", ("Gain", "GainRaw"), o["gain"], integer)
        if o["fps"] is not None:
            enable = self._node("AcquisitionFrameRateEnable", "AcquisitionFrameRateEnabled")
            if enable is not None and _writable(enable.node, genapi):
                enable.value = True
            self._set_number("fps", ("AcquisitionFrameRate", "AcquisitionFrameRateAbs"), o["fps"], False)
        self._configure_trigger()
        width, height = self._node("Width"), self._node("Height")
        if width is None or height is None:
            raise ValueError(
                f"camera {self.name!r}: the device has no Width/Height features; fxis cannot tell its image size"
            )
        self._layout = image_layout(self._pixel_format, width.value, height.value, o["raw"])
        self._period_ns = self._read_period()

    def _configure_trigger(self) -> None:
        software = self.options["trigger"] == "software"
        mode = self._node("TriggerMode")
        selector = self._node("TriggerSelector")
        if software:
            if self._node("TriggerSoftware") is None or mode is None or self._node("TriggerSource") is None:
                raise self._refuse(
                    "trigger",
                    "software triggering needs the device's TriggerMode, "
                    "TriggerSource and TriggerSoftware features, which it "
                    "lacks; it allows trigger=free only",
                )
            if selector is not None:
                for name in ("FrameStart", "AcquisitionStart"):
                    if self._set_enum(None, selector, name, quiet=True):
                        break
            self._set_enum("trigger", self._node("TriggerSource"), "Software")
            self._set_enum("trigger", mode, "On")
        elif mode is not None:  # a device left in trigger mode would never stream freely
            if selector is not None:
                self._set_enum(None, selector, "FrameStart", quiet=True)
            self._set_enum(None, mode, "Off", quiet=True)

    def _read_period(self) -> int:
        if self.supports_trigger:
            return 0
        _, genapi, _ = _sdk()
        node = self._node(
            "ResultingFrameRate", "AcquisitionResultingFrameRate", "AcquisitionFrameRate", "AcquisitionFrameRateAbs"
        )
        try:
            fps = float(node.value) if node is not None and _readable(node.node, genapi) else 0.0
        except Exception:  # some devices compute it only while acquiring
            fps = 0.0
        return round(1e9 / fps) if fps > 0 else 0

    # -- the Camera interface ------------------------------------------------------------

    def trigger(self) -> None:
        ia = self._ia
        if ia is None:
            raise CameraLost(f"camera {self.name!r} is not open")
        ia.remote_device.node_map.TriggerSoftware.execute()

    def open(self) -> None:
        core, _, gentl = _sdk()
        files = self._producers()
        self._harvester = _harvester(core)
        try:
            for cti in files:
                self._harvester.add_file(cti)
            self._harvester.update()
            infos = self._harvester.device_info_list
            index = self._pick_device(infos, files)
            try:
                self._ia = self._harvester.create(index)
            except gentl.GenericException as exc:
                raise RuntimeError(
                    f"camera {self.name!r}: cannot open device "
                    f"{_prop(infos[index], 'id_')!r}: {_short(exc)} "
                    f"(is another program using it?)"
                ) from None
            try:
                self._ia.num_buffers = max(8, self._ia.min_num_buffers)
            except Exception:
                log.debug("camera %s keeps the producer's number of buffers", self.name, exc_info=True)
            # fetch waits for the producer's new-buffer event in slices of this many ms (a
            # buffer ends a slice at once): harvesters' 1 ms slices cost CPU while idle
            self._ia.timeout_period_on_update_event_data_call = _EVENT_WAIT_MS
            self._configure()
            self._incomplete = 0
            self._last_device_id = None
            self._ia.add_callback(self._ia.Events.INCOMPLETE_BUFFER, _incomplete_counter(core, self))
            self._ia.start()
            self._last_frame_s = time.monotonic()
            if self.options["timestamp"] in ("device", "ptp"):
                self._fit = None
                self._check_device_timestamps()
        except BaseException:
            self.close()
            raise
        log.info(
            "camera %s: %s device %s, %s %s, %s",
            self.name,
            ", ".join(files),
            _prop(infos[index], "id_"),
            self._pixel_format,
            self._layout,
            f"{1e9 / self._period_ns:.2f} fps" if self._period_ns else "fps unknown",
        )

    def _check_device_timestamps(self) -> None:
        """Start-up looks at one buffer: device timestamps need the device to set them."""
        _, _, gentl = _sdk()
        if self.supports_trigger:
            self.trigger()
        buffer = self._ia.try_fetch(timeout=_FIRST_FRAME_S)
        if buffer is None:
            raise RuntimeError(
                f"camera {self.name!r}: no frame within {_FIRST_FRAME_S:.0f} s to check "
                f"its timestamps (timestamp=device)"
            )
        with buffer:
            try:
                _ = buffer.module.timestamp_ns  # raises if the buffers carry no ns timestamp
                self._device_ns = True
            except gentl.GenericException:
                try:
                    _ = buffer.module.timestamp
                except gentl.GenericException as exc:
                    raise self._refuse(
                        "timestamp",
                        f"the device does not timestamp its buffers ({_short(exc)}); it allows timestamp=host only",
                    ) from None
                self._device_ns = False
        tick_ns = 1.0
        if not self._device_ns:
            frequency = 0
            try:
                frequency = self._ia.device.module.timestamp_frequency
            except gentl.GenericException:
                node = self._node("GevTimestampTickFrequency")
                frequency = node.value if node is not None else 0
            if not frequency:
                raise self._refuse(
                    "timestamp", "the device's timestamp tick frequency is unknown; it allows timestamp=host only"
                )
            tick_ns = 1e9 / frequency
        self._fit = (
            PtpClock(timebase.service_and_tai, tick_ns)
            if self.options["timestamp"] == "ptp"
            else DeviceClockFit(tick_ns=tick_ns)
        )

    def grab(self, timeout: float) -> Capture | None:
        _, genapi, gentl = _sdk()
        if self._ia is None:
            raise CameraLost(f"camera {self.name!r} is not open")
        try:
            buffer = self._ia.try_fetch(timeout=timeout)
        except (gentl.GenericException, genapi.GenericException) as exc:
            raise CameraLost(f"the producer reports {_short(exc)}") from None
        if buffer is None:
            self._check_alive()
            return None
        t_host = timebase.now()
        self._last_frame_s = time.monotonic()
        with buffer:  # re-queued on exit: everything we keep is copied out before
            try:
                component = buffer.payload.components[0]
                fmt = component.data_format
                width, height = component.width, component.height
                if fmt != self._pixel_format or (height, width) != (self._layout.height, self._layout.width):
                    raise ValueError(
                        f"a {fmt} {width}x{height} buffer, but the ring holds "
                        f"{self._pixel_format} {self._layout.width}x{self._layout.height}"
                    )
                image = to_image(component.data, fmt, width, height, self.options["raw"])
                device_id = _frame_id(buffer, gentl)
                t_capture = self._device_time(buffer, t_host, gentl) if self._fit is not None else t_host
            except (gentl.GenericException, genapi.GenericException, ValueError, IndexError, AttributeError) as exc:
                self.frames_dropped += 1
                log.warning("camera %s: frame dropped: %s", self.name, _short(exc))
                return None
        return Capture(image, self._next_index(device_id), t_capture)

    def _device_time(self, buffer, t_host: int, gentl) -> int:
        try:
            ticks = buffer.module.timestamp_ns if self._device_ns else buffer.module.timestamp
        except gentl.GenericException:
            return t_host
        self._fit.add(ticks, t_host)
        return self._fit.to_host(ticks)

    def _next_index(self, device_id: int | None) -> int:
        """Frame index: +1 per frame, +n where the device's frame ids skip n (lost frames).
        Without device frame ids, incomplete buffers are the lost frames we know of."""
        step = 1
        if device_id is not None and self._last_device_id is not None and device_id > self._last_device_id:
            step = device_id - self._last_device_id
            self.frames_dropped += step - 1
        elif device_id is None and self._incomplete:
            self.frames_dropped += self._incomplete
        self._incomplete = 0
        self._last_device_id = device_id
        self._k += step
        return self._k

    def _check_alive(self) -> None:
        """Silence may be a lost device: after a second of it, read a register (not a cached value)."""
        if time.monotonic() - self._last_frame_s < _PROBE_AFTER_S:
            return
        self._last_frame_s = time.monotonic()
        _, genapi, gentl = _sdk()
        try:
            node = self._ia.remote_device.node_map.Width
            node.node.invalidate_node()
            _ = node.value  # a read the device must answer
        except (gentl.GenericException, genapi.GenericException) as exc:
            raise CameraLost(f"the device does not answer: {_short(exc)}") from None

    def close(self) -> None:
        ia, harvester = self._ia, self._harvester
        self._ia = self._harvester = None
        if ia is not None:
            try:
                ia.remove_callbacks()
                ia.stop()
                ia.destroy()
            except Exception:
                log.debug("camera %s: releasing the device failed", self.name, exc_info=True)
        if harvester is not None:
            try:
                harvester.reset()
            except Exception:
                log.debug("camera %s: releasing the producer failed", self.name, exc_info=True)

    @classmethod
    def discover(cls) -> list[dict]:
        """Every device of the producers GENICAM_GENTL64_PATH names (and no others)."""
        core, _, _ = _sdk()
        files = producers_from_env()
        if not files:
            raise LookupError(
                f"no GenTL producer: ${GENTL_PATH_VAR} "
                f"({os.environ.get(GENTL_PATH_VAR, 'not set')!r}) names no folder "
                f"holding a .cti file"
            )
        found = []
        for cti in files:
            harvester = _harvester(core)
            try:
                harvester.add_file(cti)
                harvester.update()
                for i, info in enumerate(harvester.device_info_list):
                    found.append(
                        {
                            "id": _prop(info, "serial_number") or _prop(info, "id_"),
                            "model": " ".join(filter(None, (_prop(info, "vendor"), _prop(info, "model")))),
                            "format": _current_format(core, harvester, i),
                            "device_id": _prop(info, "id_"),
                            "cti": cti,
                        }
                    )
            finally:
                harvester.reset()
        return found


def _incomplete_counter(core, camera: GenicamCamera):
    """A harvesters callback that counts the incomplete buffers it discards."""

    class Counter(core.Callback):
        def emit(self, context=None) -> None:
            camera._incomplete += 1

    return Counter()


def _prop(info, name: str) -> str:
    """A device-info property, '' if the producer does not provide it."""
    try:
        value = getattr(info, name)
    except Exception:  # GenTL NotAvailable and the like
        return ""
    return "" if value is None else str(value)


def _frame_id(buffer, gentl) -> int | None:
    try:
        value = int(buffer.module.frame_id)
    except (gentl.GenericException, AttributeError):
        return None
    return value or None  # 0: the producer does not number frames


def _current_format(core, harvester, index: int) -> str:
    """The device's pixel format, read through a read-only (else a short exclusive) connection;
    '?' if the device is in use."""
    for privilege in ("read_only", "exclusive"):
        try:
            ia = harvester.create(
                index, config=core.ParameterSet({core.ParameterKey.DEVICE_OWNERSHIP_PRIVILEGE: privilege})
            )
        except Exception:
            continue
        try:
            return str(ia.remote_device.node_map.PixelFormat.value)
        except Exception:
            return "?"
        finally:
            ia.destroy()
    return "? (in use)"
