"""The compiled parts are listed once (fxis_shm/_compiledparts.py) and every build file reads that list."""

from __future__ import annotations

import pathlib
import subprocess
import sys

from fxis_shm import _compiled, _compiledparts

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_every_listed_source_exists_and_every_c_file_of_the_package_is_listed():
    listed = set(_compiledparts.sources())
    assert [f for f in listed if not (ROOT / f).is_file()] == []
    on_disk = {str(p.relative_to(ROOT)) for p in (ROOT / "fxis_shm").rglob("*.[ch]")}
    assert on_disk - listed == set(), "a C file the build does not know of"


def test_the_runtime_checks_the_modules_the_build_compiles():
    assert _compiled.MODULES == _compiledparts.MYPYC_MODULES
    assert _compiled.GROUP == _compiledparts.GROUP + "__mypyc"


def test_setup_py_and_the_makefile_name_no_compiled_file_themselves():
    setup_py = (ROOT / "setup.py").read_text()
    makefile = (ROOT / "Makefile").read_text()
    for source in _compiledparts.sources():
        assert source not in setup_py
        assert source not in makefile
    assert "_compiledparts.py" in setup_py and "_compiledparts.py" in makefile


def test_the_list_prints_for_make():
    printed = subprocess.run(
        [sys.executable, str(ROOT / "fxis_shm" / "_compiledparts.py")], capture_output=True, text=True, check=True
    )
    assert printed.stdout.split() == _compiledparts.sources()


def test_the_sdist_carries_every_header_whatever_setuptools_says():
    manifest = (ROOT / "MANIFEST.in").read_text()
    assert "recursive-include fxis_shm *.c *.h" in manifest
    assert "LICENSE" in manifest


def test_the_version_is_written_once():
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert 'dynamic = ["version"]' in pyproject
    assert 'version = { attr = "fxis_shm.__version__" }' in pyproject
