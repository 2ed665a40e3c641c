"""The Aravis fake camera held directly (no fxis service): TriggerMode=On,
TriggerSource=Software, a stream of a few buffers; ``trigger()`` executes TriggerSoftware
and ``frame(timeout)`` pops what arrived. The action-command responder fires ``trigger``."""

from __future__ import annotations

from fxis_shm.workers.backends.aravis_library import load_aravis
from fxis_shm.workers.backends.aravis_ptp import camera_ptp

N_BUFFERS = 8


class TriggeredCamera:
    def __init__(self, device_id: str):
        self.Aravis, self.GLib = load_aravis()
        Aravis = self.Aravis
        self.cam = Aravis.Camera.new(device_id)
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
