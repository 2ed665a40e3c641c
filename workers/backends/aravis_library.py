"""Aravis itself, as the aravis backend loads it (PyGObject's introspection of libaravis, the
``aravis`` extra), and the cameras it finds (``fxis cameras``)."""

from __future__ import annotations

import itertools
import socket
import time

from fxis_shm.wire import gvcp_action, gvcp_register

PROBE_TIMEOUT_S = 0.3  # per READREG of the control register; a device on the network answers in ms
PROBE_TRIES = 3
_probe_ids = itertools.count(1)
IN_USE = "? (in use: another application controls it)"
SILENT = "? (it did not answer a register read: not opened)"

EXTRA_HINT = (
    "the aravis backend needs PyGObject and Aravis' introspection data: "
    "pip install 'fxis-shm[aravis]' and, on Debian/Ubuntu, apt-get install gir1.2-aravis-0.8 "
    "(scripts/install-system-packages.sh)"
)


def load_aravis():
    """(Aravis, GLib) from PyGObject; ImportError naming the ``aravis`` extra if missing."""
    try:
        import gi

        gi.require_version("Aravis", "0.8")
        from gi.repository import Aravis, GLib
    except (ImportError, ValueError) as exc:  # ValueError: gi is there, Aravis' typelib is not
        raise ImportError(f"{EXTRA_HINT} ({type(exc).__name__}: {exc})") from exc
    return Aravis, GLib


def devices() -> list[dict]:
    """Every camera Aravis finds: its id, model, vendor, serial, protocol, address and format."""
    Aravis, GLib = load_aravis()
    Aravis.update_device_list()
    found = []
    for i in range(Aravis.get_n_devices()):
        device_id = Aravis.get_device_id(i)
        entry = {
            "id": device_id,
            "model": Aravis.get_device_model(i),
            "vendor": Aravis.get_device_vendor(i),
            "serial": Aravis.get_device_serial_nbr(i),
            "protocol": Aravis.get_device_protocol(i),
            "address": Aravis.get_device_address(i),
        }
        if entry["protocol"] == "GigEVision":
            # opening it tries to take control: a service's camera silent for its heartbeat's timeout
            # (3 s) would go to the listing, and a camera that does not answer would hold it for seconds
            controlled = controlled_elsewhere(entry["address"])
            if controlled is not False:
                entry["format"] = IN_USE if controlled else SILENT
                found.append(entry)
                continue
        try:
            cam = Aravis.Camera.new(device_id)
            _, _, w, h = cam.get_region()
            fmt = f"{w}x{h} {cam.get_pixel_format_as_string()}"
            if cam.is_frame_rate_available():
                fmt += f" {cam.get_frame_rate():g} fps"
            del cam
        except GLib.Error as exc:
            fmt = f"? (cannot open it: {exc.message})"
        entry["format"] = fmt
        found.append(entry)
    return found


def controlled_elsewhere(address: str) -> bool | None:
    """Whether an application controls the GigE Vision device at ``address`` (its control
    channel privilege register, read with one GVCP READREG, which needs no control); True also
    when it refuses the read (exclusive access), None when it does not answer."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for _ in range(PROBE_TRIES):
            req_id = next(_probe_ids) % 0xFFFF + 1
            try:
                sock.sendto(
                    gvcp_register.encode_readreg(gvcp_register.CCP_REGISTER, req_id), (address, gvcp_action.GVCP_PORT)
                )
            except OSError:
                return None
            deadline = time.monotonic() + PROBE_TIMEOUT_S
            while (left := deadline - time.monotonic()) > 0:
                sock.settimeout(left)
                try:
                    answer = gvcp_register.decode_readreg_ack(sock.recv(64), req_id)
                except (TimeoutError, OSError):
                    break
                if answer is not None:
                    status, value = answer
                    if status == gvcp_action.STATUS_ACCESS_DENIED:
                        return True
                    return (
                        bool(value & gvcp_register.CCP_CONTROL_BITS) if status == gvcp_action.STATUS_SUCCESS else None
                    )
    return None
