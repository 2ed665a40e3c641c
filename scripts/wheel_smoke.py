"""The smoke test of an installed wheel, as a user gets it: run with the Python of a fresh venv
the wheel was installed into, from outside any checkout (scripts/build-wheels.sh does both; so
does cibuildwheel's test-command, pyproject.toml). Exits 0 when every check holds, else prints
the first that failed and exits 1.

Checks: fxis_shm imports from site-packages (no checkout on sys.path) with every compiled part
running compiled; the console script answers --help; `fxis run` serves two synthetic cameras
whose tuple's pixels name the frames its metadata names; `fxis status` answers; the workers
are found in the installed package; the service stops cleanly on SIGTERM.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import sysconfig
import time


def fail(what: str) -> None:
    print(f"wheel smoke test: FAILED: {what}", file=sys.stderr)
    sys.exit(1)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def main() -> None:
    import fxis_shm
    from fxis_shm import Client, RequestTimeout, read_stamp

    site = sysconfig.get_paths()["purelib"]
    if not fxis_shm.__file__.startswith(os.path.realpath(site)) and not fxis_shm.__file__.startswith(site):
        fail(f"fxis_shm imported from {fxis_shm.__file__}, not from this venv's site-packages {site}")
    import fxis_shm.workers

    if not fxis_shm.workers.__file__.startswith(os.path.dirname(fxis_shm.__file__)):
        fail(f"fxis_shm.workers imported from {fxis_shm.workers.__file__}")
    if not fxis_shm.compiled:
        fail(f"the hot path is not compiled: {fxis_shm._compiled.status()}")
    fxis = os.path.join(os.path.dirname(sys.executable), "fxis")
    helped = subprocess.run([fxis, "--help"], capture_output=True, text=True, timeout=60)
    if helped.returncode != 0 or "run" not in helped.stdout:
        fail(f"fxis --help exited {helped.returncode}: {helped.stderr.strip()[:300]}")

    endpoint = f"tcp://127.0.0.1:{free_port()}"
    name = f"smoke{os.getpid()}"
    service = subprocess.Popen(
        [fxis, "run", "--name", name, "--endpoint", endpoint, "--pub", f"tcp://127.0.0.1:{free_port()}",
         "--events", f"tcp://127.0.0.1:{free_port()}", "--http", "off",
         "--camera", "a=synthetic:width=160,height=120", "--camera", "b=synthetic:width=160,height=120"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        with Client(endpoint, timeout=1.0) as client:
            deadline = time.monotonic() + 60
            while True:
                if service.poll() is not None:
                    fail(f"fxis run exited {service.returncode}: {service.stderr.read().strip()[-500:]}")
                try:
                    client.status()
                    break
                except RequestTimeout:
                    if time.monotonic() > deadline:
                        fail("fxis run did not answer status within 60 s")
            pair = client.tuple(timeout=10)
            for frame in pair.values():
                stamped = read_stamp(frame.image)
                if stamped != frame.frame_id:
                    fail(f"camera {frame.camera}: the pixels name frame {stamped}, the metadata {frame.frame_id}")
        status = subprocess.run([fxis, "status", "--endpoint", endpoint], capture_output=True, text=True, timeout=60)
        if status.returncode != 0 or "a" not in status.stdout:
            fail(f"fxis status exited {status.returncode}: {status.stderr.strip()[:300]}")
    finally:
        if service.poll() is None:
            service.send_signal(signal.SIGTERM)
            try:
                service.wait(30)
            except subprocess.TimeoutExpired:
                service.kill()
                service.wait()
    if service.returncode != 0:
        fail(f"fxis run exited {service.returncode} on SIGTERM")
    print(f"wheel smoke test: passed (fxis-shm {fxis_shm.__version__}, Python {sys.version.split()[0]}, compiled)")


if __name__ == "__main__":
    main()
