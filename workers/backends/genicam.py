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
them (genicam_features.py); a key the device lacks or a value it refuses stops
start-up with a ValueError that names the camera, the key and what the device
allows.

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

from fxis_shm.core import timebase
from fxis_shm.core.clocks import DeviceClockFit, PtpClock
from fxis_shm.service.camerakinds import GENTL_PATH_VAR
from fxis_shm.shm.ring import FrameLayout

from . import genicam_tuning
from .base import Camera, CameraLost, Capture
from .genicam_features import DeviceFeatures, refusal, short_error
from .genicam_timing import SilenceWatch, device_clock
from .pixelformats import to_image

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
        self._silence = SilenceWatch()
        self._features: DeviceFeatures | None = None
        self._pixel_format = ""

    # -- configuration ---------------------------------------------------------------

    def _refuse(self, key: str, why: str) -> ValueError:
        return refusal(self.name, key, why)

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

    def _configure(self) -> None:
        _, genapi, _ = _sdk()
        self._features = DeviceFeatures(self._ia.remote_device.node_map, genapi, self.name)
        self._pixel_format, self._layout = self._features.configure(self.options)
        self._period_ns = 0 if self.supports_trigger else self._features.frame_period_ns()

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
                    f"{_prop(infos[index], 'id_')!r}: {short_error(exc)} "
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
            self._silence = SilenceWatch()
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
                        f"the device does not timestamp its buffers ({short_error(exc)}); "
                        "it allows timestamp=host only",
                    ) from None
                self._device_ns = False
        tick_ns = 1.0
        if not self._device_ns:
            frequency = 0
            try:
                frequency = self._ia.device.module.timestamp_frequency
            except gentl.GenericException:
                node = self._features.node("GevTimestampTickFrequency")
                frequency = node.value if node is not None else 0
            if not frequency:
                raise self._refuse(
                    "timestamp", "the device's timestamp tick frequency is unknown; it allows timestamp=host only"
                )
            tick_ns = 1e9 / frequency
        self._fit = device_clock(self.options["timestamp"], tick_ns)

    def grab(self, timeout: float) -> Capture | None:
        _, genapi, gentl = _sdk()
        if self._ia is None:
            raise CameraLost(f"camera {self.name!r} is not open")
        try:
            buffer = self._ia.try_fetch(timeout=timeout)
        except (gentl.GenericException, genapi.GenericException) as exc:
            raise CameraLost(f"the producer reports {short_error(exc)}") from None
        if buffer is None:
            self._check_alive()
            return None
        t_host = timebase.now()
        self._silence.frame_arrived()
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
                log.warning("camera %s: frame dropped: %s", self.name, short_error(exc))
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
        if self._silence.check_due(_PROBE_AFTER_S) is None:
            return
        _, genapi, gentl = _sdk()
        try:
            node = self._ia.remote_device.node_map.Width
            node.node.invalidate_node()
            _ = node.value  # a read the device must answer
        except (gentl.GenericException, genapi.GenericException) as exc:
            raise CameraLost(f"the device does not answer: {short_error(exc)}") from None

    # -- settings at run time (genicam_tuning.py) ---------------------------------------

    def settings(self, extra=()) -> dict[str, dict]:
        return genicam_tuning.describe_all(self._features, self.options["trigger"], extra, _sdk()[1])

    def set_live(self, values) -> None:
        genicam_tuning.set_live(self._features, values)
        self.options.update({k: v for k, v in values.items() if k in self.options})
        if not self.supports_trigger:
            self._period_ns = self._features.frame_period_ns()

    def features(self) -> list[dict]:
        return genicam_tuning.features_of(self._features, _sdk()[1])

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
