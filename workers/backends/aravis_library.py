"""Aravis itself, as the aravis backend loads it (PyGObject's introspection of libaravis, the
``aravis`` extra), and the cameras it finds (``fxis cameras``)."""

from __future__ import annotations

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
