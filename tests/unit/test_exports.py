"""The public API is exactly what docs/quickstart.md documents, all importable from ``fxis_shm``."""

import pathlib
import re
import subprocess
import sys

import fxis_shm

QUICKSTART = pathlib.Path(__file__).resolve().parents[2] / "docs" / "quickstart.md"


def documented_names() -> set[str]:
    text = QUICKSTART.read_text()
    section = text.split("## The public API", 1)[1].split("\n## ", 1)[0]
    return set(re.findall(r"`([A-Za-z_]+)`", section)) - {"fxis_shm", "__all__"}


def test_all_is_exactly_the_documented_api():
    assert sorted(fxis_shm.__all__) == sorted(documented_names())
    assert len(set(fxis_shm.__all__)) == len(fxis_shm.__all__)


def test_every_exported_name_imports_and_every_error_is_an_fxis_error():
    for name in fxis_shm.__all__:
        value = getattr(fxis_shm, name)
        if isinstance(value, type) and issubclass(value, Exception):
            assert issubclass(value, fxis_shm.FxisError), name


def test_module_paths_keep_working():
    from fxis_shm.client.client import Client
    from fxis_shm.client.pubsub import Subscriber

    assert Client is fxis_shm.Client and Subscriber is fxis_shm.Subscriber


def test_no_public_name_outside_all():
    for name in fxis_shm.__all__:  # the names imported on first use are there once used
        getattr(fxis_shm, name)
    public = {n for n, v in vars(fxis_shm).items() if not n.startswith("_") and not isinstance(v, type(fxis_shm))}
    assert public == set(fxis_shm.__all__)


def test_bad_arguments_to_the_public_api_raise_fxis_errors(tmp_path):
    import numpy as np
    import pytest

    from fxis_shm.formats.stamp import write_stamp

    with pytest.raises(fxis_shm.InvalidArgument, match="takes its options by keyword"):
        fxis_shm.Client(["tcp://127.0.0.1:9", "tcp://127.0.0.1:10"], 2.0)
    with pytest.raises(fxis_shm.FxisError, match="local must be one of"):
        fxis_shm.Client("tcp://127.0.0.1:9", local="sometimes")
    with pytest.raises(fxis_shm.ConfigError, match="cannot read the key file"):
        fxis_shm.ClientKeys.from_files(str(tmp_path / "missing.key"), str(tmp_path / "me.key_secret"))
    with pytest.raises(fxis_shm.FxisError, match="cannot hold a stamp"):
        write_stamp(np.zeros((4, 2), np.uint8), 7)


def test_importing_the_package_leaves_the_client_unimported():
    # every process of a service imports fxis_shm: the client's modules wait for first use
    code = "import sys, fxis_shm; print(sorted(m for m in sys.modules if m.startswith('fxis_shm.client')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
