"""The Aravis fake camera held directly (no fxis service): TriggerMode=On,
TriggerSource=Software, a stream of a few buffers; ``trigger()`` executes TriggerSoftware
and ``frame(timeout)`` pops what arrived. The action-command responder fires ``trigger``."""

from __future__ import annotations

import threading
import time

from fxis_shm.workers.backends.aravis_library import load_aravis
from fxis_shm.workers.backends.aravis_ptp import camera_ptp

N_BUFFERS = 8
CONTROL_TIMEOUT_S = 20.0


class TriggeredCamera:
    def __init__(self, device_id: str):
        self.Aravis, self.GLib = load_aravis()
        Aravis = self.Aravis
        self.cam = self._open_with_control(device_id)
        # Another application may have left it acquiring: the emulator then goes on streaming to
        # that application's address, which it looked up when it started, whatever address this
        # one sets (make test run 49: a camera taken from a stopped service never sent a frame here)
        self.cam.stop_acquisition()
        device = self.cam.get_device()
        self.control_lost = threading.Event()  # set on Aravis' heartbeat thread
        lost = self.control_lost
        device.connect("control-lost", lambda *_: lost.set())
        self.cam.set_region(0, 0, 64, 48)
        self.cam.set_pixel_format_from_string("Mono8")
        self.cam.set_acquisition_mode(Aravis.AcquisitionMode.CONTINUOUS)
        self.cam.set_trigger("Software")  # TriggerSelector FrameStart, TriggerMode On, TriggerSource Software
        # an emulator on a loopback address sends through lo, which a packet socket never sees
        self.cam.gv_set_stream_options(Aravis.GvStreamOption.PACKET_SOCKET_DISABLED)
        self.stream = self.cam.create_stream(None, None)
        payload = self.cam.get_payload()
        for _ in range(N_BUFFERS):
            self.stream.push_buffer(Aravis.Buffer.new_allocate(payload))
        self.cam.start_acquisition()

    def _open_with_control(self, device_id: str):
        """The camera, opened once its control is ours: Aravis opens it without control when another
        application has it (an `fxis cameras` of another test, for a moment), and then each write
        times out."""
        deadline = time.monotonic() + CONTROL_TIMEOUT_S
        while True:
            cam = self.Aravis.Camera.new(device_id)
            if cam.get_device().is_controller():
                return cam
            del cam
            if time.monotonic() > deadline:
                raise RuntimeError(
                    f"{device_id}: no control of the camera within {CONTROL_TIMEOUT_S} s (another application has it)"
                )
            time.sleep(0.2)

    def feature(self, name: str) -> str:
        return self.cam.get_device().get_string_feature_value(name)

    def ptp(self):
        return camera_ptp(self.cam, self.GLib)

    def trigger(self) -> None:
        self.cam.software_trigger()

    def frame(self, timeout: float):
        """(system timestamp ns, block id) of the next complete frame, or None by ``timeout``."""
        buffer = self.stream.timeout_pop_buffer(int(timeout * 1e6))
        if buffer is None:
            return None
        try:
            if buffer.get_status() != self.Aravis.BufferStatus.SUCCESS:
                return None
            return buffer.get_system_timestamp(), buffer.get_frame_id()
        finally:
            self.stream.push_buffer(buffer)

    def close(self) -> None:
        try:
            self.cam.stop_acquisition()
        except self.GLib.Error:
            pass  # the emulator may be gone already
        self.stream = self.cam = None
