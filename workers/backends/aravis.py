"""GigE Vision and USB3 Vision cameras through Aravis (PyGObject; the ``aravis`` extra).

    --camera left=aravis:device=Aravis-Fake-GV01,fps=20,width=640,height=480

``device`` is an id as ``fxis cameras`` lists it (Aravis' device id; an IP
address or a serial number work too); without it the first camera Aravis finds
is used. The keys are set through Aravis' camera API (aravis_settings.py):
settings the camera refuses stop start-up with a ValueError naming the key and
what the camera allows; settings that are not given stay as the camera has them.

Frames: a pool of buffers is queued on the Aravis stream, ``grab`` pops one,
copies the image out (Bayer demosaiced to BGR, RGB8 reordered to BGR, unless
``raw=true``) and queues the buffer again. A buffer Aravis could not complete
(missing packets, timeout) is counted in ``frames_dropped`` and never returned,
as are frames whose block ids never arrived (a gap in the ids). GigE Vision
block ids are 16-bit (1..65535, 0 is reserved): they are unwrapped into a 64-bit
counter (blockids.py), so frame ids keep increasing.

Time (docs/cameras.md): ``timestamp=host`` (default) is the moment Aravis saw
the frame arrive, a wall-clock time mapped onto CLOCK_MONOTONIC with both
clocks read right after the buffer is popped; ``timestamp=device`` is the
camera's own timestamp mapped onto CLOCK_MONOTONIC by a fitted drift and offset
(``fxis_shm.core.clocks.DeviceClockFit``).

Faults: no frame for a while makes ``grab`` probe the camera's control channel
from a helper thread (reading the GigE Vision control-privilege register, or a
feature for other cameras); a failed probe, a probe showing that this host lost
control of the camera (it restarted), or Aravis' ``control-lost`` signal raise
CameraLost; the worker then closes and reopens the camera with backoff.

Threads: the capture loop grabs and applies settings, the worker's trigger threads (the
coordinator's "now" and the timer of capture at T and lockstep, workers/triggers.py) fire
TriggerSoftware, the probe reads a register. Aravis serializes the GVCP transactions of a
device, but its GenICam node map is not made for concurrent use: every use of the camera
object (``_cam``, ``_device``) takes ``_control``, so one thread at a time touches it. A
trigger then waits for a settings read in progress (its lateness shows in status, sync);
the stream's buffers are not the control channel and are popped without it.
"""

from __future__ import annotations

import ipaddress
import logging
import threading
import time
from typing import Any

import numpy as np

from fxis_shm.core import timebase
from fxis_shm.core.clocks import wall_to_monotonic
from fxis_shm.core.ptp import PtpState
from fxis_shm.service.camerakinds import DRIVER_BUFFERS
from fxis_shm.shm.ring import FrameLayout
from fxis_shm.wire import gvcp_register

from . import aravis_tuning
from .aravis_library import devices, load_aravis
from .aravis_ptp import camera_ptp
from .aravis_settings import PIXEL_FORMATS, apply_options
from .base import Camera, CameraLost, Capture
from .blockids import FrameCounter
from .genicam_timing import SilenceWatch, device_clock, period_ns
from .pixelformats import image_layout

log = logging.getLogger("camera")

N_BUFFERS = DRIVER_BUFFERS  # frames Aravis can hold for us; ~0.6 s at 20 fps if the worker stalls
MIN_SOCKET_BUFFER = 1 << 20  # bytes; the kernel caps it at net.core.rmem_max
PROBE_IDLE_S = 0.5  # probe the camera after this long without a frame (at least 4 periods)


class AravisCamera(Camera):
    kind = "aravis"

    def __init__(self, name: str, options: dict[str, Any], time_origin_ns: int):
        super().__init__(name, options, time_origin_ns)
        self._cam = self._device = self._stream = None
        self._layout: FrameLayout | None = None
        self._period_ns = 0
        self._lost = threading.Event()
        self._probe_error: str | None = None
        self._probe: threading.Thread | None = None
        self._opened = False  # has open() ever succeeded?
        self._control = threading.RLock()  # one thread at a time uses the camera object (above)

    # ---- open and configure -------------------------------------------------------------

    def open(self) -> None:
        with self._control:  # a trigger fired meanwhile waits for the configured camera
            self._open()

    def _open(self) -> None:
        Aravis, GLib = load_aravis()
        self._Aravis, self._GLib = Aravis, GLib
        device_id = self.options["device"] or self._first_device()
        self.device_id = device_id
        try:
            cam = Aravis.Camera.new(device_id)
        except GLib.Error as exc:
            message = f"Aravis cannot open device {device_id!r}: {exc.message}"
            if not self._opened:  # at start-up, say what it sees (a reconnection retries quickly)
                Aravis.update_device_list()
                seen = [Aravis.get_device_id(i) for i in range(Aravis.get_n_devices())]
                message += f"; it sees {', '.join(seen) if seen else 'no camera'}"
            raise RuntimeError(message) from None
        self._cam, self._device = cam, cam.get_device()
        self._lost, self._probe_error = threading.Event(), None
        lost = self._lost  # the handler must not hold self: it runs on Aravis' heartbeat thread
        self._lost_handler = self._device.connect("control-lost", lambda *_: lost.set())
        try:
            self._check_control()
            self._configure()
            self._start_stream()
        except BaseException:
            self.close()
            raise
        self._opened = True

    def _check_control(self) -> None:
        """A GigE Vision camera takes commands from one host: Aravis opens a camera another
        application controls without control, and every write would then time out (seconds
        per setting). Refused here, at once; the lost camera's retries take it once it is free."""
        if self._cam.is_gv_device() and not self._device.is_controller():
            # close() then releases it on a helper thread: Aravis' leave-control write waits out its timeouts
            self._probe_error = f"another application controls camera {self.name!r} ({self.device_id})"
            raise RuntimeError(f"{self._probe_error}; fxis takes it once that application lets go")

    def _first_device(self) -> str:
        Aravis = self._Aravis
        Aravis.update_device_list()
        if Aravis.get_n_devices() == 0:
            raise RuntimeError("Aravis finds no camera (give device=...; `fxis cameras` lists what it sees)")
        return Aravis.get_device_id(0)

    def _refuse(self, key: str, value, allowed: str) -> ValueError:
        if isinstance(value, float):
            value = f"{value:g}"
        return ValueError(f"camera {self.name!r} ({self.device_id}) refuses {key}={value}: {allowed}")

    def _configure(self) -> None:
        cam, o, GLib = self._cam, self.options, self._GLib
        try:
            cam.stop_acquisition()  # a worker that crashed may have left it running
        except GLib.Error:
            pass
        try:
            apply_options(cam, o, self._refuse, self._Aravis)
        except GLib.Error as exc:
            raise RuntimeError(
                f"camera {self.name!r} ({self.device_id}): configuration failed: {exc.message}"
            ) from None
        fmt = cam.get_pixel_format_as_string()
        if fmt not in PIXEL_FORMATS:
            raise self._refuse(
                "pixel_format",
                f"{fmt} (its current format)",
                f"fxis stores {', '.join(PIXEL_FORMATS)}; choose one with pixel_format=",
            )
        self._format = fmt
        self._pixel = PIXEL_FORMATS[fmt]
        self._pfnc = cam.get_pixel_format()
        _, _, w, h = cam.get_region()
        self._width, self._height = w, h
        self._layout = image_layout(fmt, w, h, o["raw"])
        self._period_ns = 0
        if self.options["trigger"] == "free" and cam.is_frame_rate_available():
            self._period_ns = period_ns(cam.get_frame_rate())
        log.info(
            "camera %s: %s %s %dx%d %s, %s, timestamp=%s",
            self.name,
            self.device_id,
            cam.get_model_name(),
            w,
            h,
            fmt,
            f"{1e9 / self._period_ns:.3g} fps"
            if self._period_ns
            else "trigger=software"
            if self.supports_trigger
            else "frame rate unknown",
            o["timestamp"],
        )
        ptp = self.ptp()
        why = ptp.why_not_locked()
        log.info("camera %s: PTP %s", self.name, why or f"locked ({ptp.status}, offset {ptp.offset_ns} ns)")

    def _start_stream(self) -> None:
        Aravis, cam = self._Aravis, self._cam
        self._gv = cam.is_gv_device()
        if self._gv:
            # Aravis' packet socket listens on the NIC of the interface address; a camera on
            # a loopback address (an emulator) sends through lo, which it never sees.
            if ipaddress.ip_address(self._device.get_device_address().get_address().to_string()).is_loopback:
                cam.gv_set_stream_options(Aravis.GvStreamOption.PACKET_SOCKET_DISABLED)
        payload = cam.get_payload()
        self._stream = cam.create_stream(None, None)
        if self._stream is None:
            raise RuntimeError(f"camera {self.name!r} ({self.device_id}): Aravis could not create a stream")
        if self._gv:
            # A frame arrives as a burst of packets: the socket must hold a few whole frames.
            self._stream.set_property("socket-buffer", Aravis.GvStreamSocketBuffer.FIXED)
            self._stream.set_property("socket-buffer-size", max(MIN_SOCKET_BUFFER, 4 * payload))
        for _ in range(N_BUFFERS):
            self._stream.push_buffer(Aravis.Buffer.new_allocate(payload))
        shape = (self._height, self._width) + ((self._pixel.channels,) if self._pixel.channels > 1 else ())
        self._image = np.empty(shape, self._pixel.dtype)
        self._row_bytes = self._image.nbytes // self._height
        self._image_bytes = self._image.view(np.uint8).reshape(self._height, self._row_bytes)
        self._convert = None
        if self._pixel.to_bgr and not self.options["raw"]:
            import cv2

            self._convert = getattr(cv2, self._pixel.to_bgr)
            self._converted = np.empty(self._layout.shape, np.uint8)
        self._ids = FrameCounter(0xFFFF if self._gv else None)
        self._failed_since_good = 0
        # Aravis gives device timestamps in ns: it converts GigE Vision ticks with the
        # camera's timestamp tick frequency (USB3 Vision timestamps are ns already).
        self._clock = device_clock(self.options["timestamp"], tick_ns=1.0)
        if self.options["timestamp"] == "device" and self._gv and not self._device.get_timestamp_tick_frequency():
            log.warning(
                "camera %s reports no timestamp tick frequency: Aravis stamps its frames "
                "with the host's clock, so timestamp=device is the arrival time",
                self.name,
            )
        self._probe: threading.Thread | None = None
        self._warned_device_ts = False
        self._cam.start_acquisition()
        self._silence = SilenceWatch()

    # ---- what the worker asks --------------------------------------------------------------

    def trigger(self) -> None:
        with self._control:
            cam = self._cam
            if cam is None:
                raise RuntimeError(f"camera {self.name!r} is not open (lost?)")
            try:
                cam.software_trigger()  # executes TriggerSoftware
            except self._GLib.Error as exc:
                self._start_probe(None)  # why: the camera gone, or its control taken?
                raise RuntimeError(f"TriggerSoftware failed: {exc.message}") from None

    def ptp(self) -> PtpState:
        """The camera's PTP state (fxis_shm/core/ptp.py): scheduled action commands need it locked."""
        with self._control:
            if self._cam is None:
                raise RuntimeError(f"camera {self.name!r} is not open (lost?)")
            return camera_ptp(self._cam, self._GLib)

    # ---- settings at run time (aravis_tuning.py) -------------------------------------------

    def settings(self, extra=()) -> dict[str, dict]:
        with self._control:
            return aravis_tuning.describe_all(self._cam, self.options["trigger"], extra, self._Aravis)

    def set_live(self, values) -> None:
        with self._control:
            try:
                aravis_tuning.set_live(self._cam, values, self._Aravis)
            except self._GLib.Error as exc:
                self._start_probe(None)  # a refused value, or a camera gone or taken
                raise ValueError(exc.message) from None
            self.options.update({k: v for k, v in values.items() if k in self.options})
            if self.options["trigger"] == "free" and self._cam.is_frame_rate_available():
                self._period_ns = period_ns(self._cam.get_frame_rate())

    def features(self) -> list[dict]:
        with self._control:
            return aravis_tuning.features(self._cam, self._Aravis)

    # ---- frames ------------------------------------------------------------------------------

    def grab(self, timeout: float) -> Capture | None:
        Aravis = self._Aravis
        deadline = time.monotonic() + timeout
        while True:
            if self._lost.is_set():
                raise CameraLost("Aravis lost the control channel (control-lost)")
            if self._probe_error is not None:  # also while frames still come: a taken camera streams on
                raise CameraLost(self._probe_error)
            remaining = deadline - time.monotonic()
            buffer = self._stream.timeout_pop_buffer(max(0, int(remaining * 1e6)))
            mono_before = timebase.now()
            wall_now = time.time_ns()
            mono_now = (mono_before + timebase.now()) // 2
            if buffer is None:
                self._check_alive()
                return None
            self._silence.frame_arrived()
            try:
                capture = self._take(buffer, Aravis, mono_now, wall_now)
            finally:
                self._stream.push_buffer(buffer)
            if capture is not None:
                return capture
            if time.monotonic() >= deadline:
                return None

    def _take(self, buffer, Aravis, mono_now: int, wall_now: int) -> Capture | None:
        """The frame in ``buffer`` (copied out), or None if it is incomplete (counted)."""
        status = buffer.get_status()
        if status != Aravis.BufferStatus.SUCCESS:
            if status != Aravis.BufferStatus.ABORTED:
                self.frames_dropped += 1
                self._failed_since_good += 1
            return None
        if buffer.get_payload_type() not in (
            Aravis.BufferPayloadType.IMAGE,
            Aravis.BufferPayloadType.EXTENDED_CHUNK_DATA,
        ):
            self.frames_dropped += 1
            self._failed_since_good += 1
            return None
        frame_id, missing = self._ids.next(buffer.get_frame_id())
        # frames that never arrived whole: the gap in the ids minus those already counted
        self.frames_dropped += max(0, missing - self._failed_since_good)
        self._failed_since_good = 0
        image = self._image_of(buffer)
        if image is None:
            self.frames_dropped += 1
            return None
        t_host = wall_to_monotonic(buffer.get_system_timestamp(), mono_now, wall_now)
        t_capture = t_host
        if self._clock is not None:
            ticks = buffer.get_timestamp()
            if ticks > 0:
                self._clock.add(ticks, t_host)
                t_capture = self._clock.to_host(ticks)
            elif not self._warned_device_ts:
                self._warned_device_ts = True
                log.warning("camera %s sends no device timestamps: using the arrival time", self.name)
        return Capture(image, frame_id, t_capture)

    def _image_of(self, buffer) -> np.ndarray | None:
        w, h = buffer.get_image_width(), buffer.get_image_height()
        if (w, h) != (self._width, self._height) or buffer.get_image_pixel_format() != self._pfnc:
            log.warning(
                "camera %s sent a %dx%d frame of format 0x%08x; expected %dx%d %s",
                self.name,
                w,
                h,
                buffer.get_image_pixel_format(),
                self._width,
                self._height,
                self._format,
            )
            return None
        data = buffer.get_image_data()  # bytes: PyGObject copied them out of the buffer
        row = self._row_bytes
        if len(data) < row * h:
            return None
        stride = len(data) // h  # > row if the camera pads its lines
        np.copyto(self._image_bytes, np.frombuffer(data, np.uint8, count=stride * h).reshape(h, stride)[:, :row])
        if self._convert is None:
            return self._image
        import cv2

        cv2.cvtColor(self._image, self._convert, dst=self._converted)
        return self._converted

    # ---- is the camera still there? ------------------------------------------------------------

    def _idle_limit(self) -> float:
        return max(PROBE_IDLE_S, 4 * self._period_ns / 1e9)

    def _check_alive(self) -> None:
        """No frame came: after a while, probe the control channel; grab raises CameraLost
        once a probe failed."""
        idle = self._silence.check_due(self._idle_limit())
        if idle is not None:
            self._start_probe(idle)

    def _start_probe(self, idle: float | None) -> None:
        """Probe in a thread (a dead camera makes a read block for seconds), one at a time;
        ``idle`` is the silence that asked for it, None for a command the camera failed."""
        if self._probe is not None and self._probe.is_alive():
            return
        self._probe = threading.Thread(
            target=self._run_probe, args=(idle,), daemon=True, name=f"aravis-probe-{self.name}"
        )
        self._probe.start()

    def _run_probe(self, idle: float | None) -> None:
        with self._control:  # a dead camera holds it for the GVCP timeouts: close() waits for them
            self._probe_once("a command failed" if idle is None else f"no frame for {idle:.1f} s")

    def _probe_once(self, why: str) -> None:
        cam, device, GLib = self._cam, self._device, self._GLib
        if cam is None:
            return
        try:
            if self._gv:
                ccp = device.read_register(gvcp_register.CCP_REGISTER)
                if not ccp & gvcp_register.CCP_CONTROL_BITS:
                    self._probe_error = f"{why} and the camera has no controlling host any more (it restarted)"
                    return
                heartbeat_ms = device.read_register(gvcp_register.HEARTBEAT_TIMEOUT_REGISTER)
            else:
                cam.get_integer("Width")
                return
        except GLib.Error as exc:
            self._probe_error = f"{why} and the camera does not answer ({exc.message})"
            return
        # Some host controls it; this one? The control bits do not say who (Aravis' heartbeat reads
        # them and so never notices a camera taken after a silence past its heartbeat timeout).
        # As Pylon does, write the heartbeat timeout back: a camera refuses a write from a host
        # that is not its controller (the emulator ignores it), and answers every host's read.
        try:
            device.write_register(gvcp_register.HEARTBEAT_TIMEOUT_REGISTER, heartbeat_ms)
        except GLib.Error as exc:
            self._probe_error = (
                f"{why}: another application took control of the camera (it answers reads but refuses"
                f" this host's writes: {exc.message})"
            )

    # ---- close -----------------------------------------------------------------------------

    def close(self) -> None:
        with self._control:  # no trigger or probe midway: from here on they find the camera closed
            cam, stream, device = self._cam, self._stream, self._device
            self._cam = self._stream = self._device = None
        if cam is None:
            return
        lost = self._lost.is_set() or self._probe_error is not None
        if not lost:
            try:
                cam.stop_acquisition()
            except self._GLib.Error:
                lost = True
        try:
            device.disconnect(self._lost_handler)
        except Exception:
            pass
        if lost:
            # Finalizing the objects of a camera that is gone blocks on control-channel
            # timeouts (seconds): let a thread do it, so the worker can retry meanwhile.
            objects = [stream, cam, device]
            del stream, cam, device
            threading.Thread(target=objects.clear, daemon=True, name="aravis-release").start()
        else:
            del stream, cam, device

    # ---- fxis cameras ----------------------------------------------------------------------

    @classmethod
    def discover(cls) -> list[dict]:
        return devices()
