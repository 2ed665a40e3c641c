"""Everything runs from a source checkout, without fxis-shm installed
(``PYTHONPATH=<checkout>``): the top-level workers/ folder is then found as
fxis_shm.workers by fxis_shm/_sourcetree.py, in the CLI and in every child."""

from __future__ import annotations

import json
import os
import site
import subprocess
import sys
from pathlib import Path

import pytest

from fxis_shm.service.launch import ServiceProcess

from ..conftest import assert_nothing_left

pytestmark = pytest.mark.integration
CHECKOUT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bare_python(tmp_path_factory) -> str:
    """A fresh venv without fxis-shm that sees this interpreter's dependencies
    through one .pth line: the .pth files there (the editable install's finder
    among them) are not run, so fxis_shm can only come from PYTHONPATH."""
    venv = tmp_path_factory.mktemp("bare") / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    python = str(venv / "bin" / "python")
    bare_site = subprocess.run(
        [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True,
        text=True,
        check=True,
        timeout=30,
    ).stdout.strip()
    Path(bare_site, "fxis-test-deps.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    return python


@pytest.fixture
def checkout_env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(CHECKOUT)}


def test_the_workers_package_is_the_checkouts_folder(bare_python, checkout_env, tmp_path):
    code = (
        "import sys, fxis_shm.workers.camera as c; "
        "print(c.__file__); print(any('editable' in type(f).__module__ for f in sys.meta_path))"
    )
    result = subprocess.run(
        [bare_python, "-c", code], cwd=tmp_path, env=checkout_env, capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stderr
    path, editable_finder = result.stdout.split()
    assert Path(path) == CHECKOUT / "workers" / "camera.py"
    assert editable_finder == "False"  # found without an install's help


def test_fxis_cameras_runs_from_the_checkout(bare_python, checkout_env, tmp_path):
    """The discovery child finds the backends in the checkout's workers/: with the simulated GenTL
    producer the genicam wheel ships (viky.cti, three devices) on the producer path, it lists them."""
    import genicam

    from fxis_shm.service.camerakinds import GENTL_PATH_VAR

    viky = os.path.join(os.path.dirname(genicam.__file__), "viky.cti")
    result = subprocess.run(
        [bare_python, "-m", "fxis_shm.cli", "cameras", "--json"],
        cwd=tmp_path,
        env={**checkout_env, GENTL_PATH_VAR: os.path.dirname(viky)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    listing = json.loads(result.stdout)
    assert "genicam" not in listing["unavailable"] and "aravis" not in listing["unavailable"], listing
    listed = [c for c in listing["cameras"] if c["kind"] == "genicam"]
    assert [c["id"] for c in listed] == ["0", "1", "2"], listing
    assert all("Viky" in c["model"] and c["cti"] == viky for c in listed), listed


def test_a_service_runs_from_the_checkout(bare_python, checkout_env, tmp_path):
    with open(tmp_path / "service.log", "w") as log:
        svc = ServiceProcess(
            ["--camera", "a=synthetic:width=64,height=48,fps=50"], stderr=log, python=bare_python, env=checkout_env
        )
        try:
            with svc.start().client(timeout=5.0) as client:
                assert client.tuple().keys() == {"a"}  # the camera worker stored frames
        finally:
            svc.stop()
    assert_nothing_left(svc.name)
