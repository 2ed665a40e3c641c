"""Builds the compiled parts; everything else is in pyproject.toml. Which parts there are is
fxis_shm/_compiledparts.py's one list: the C helpers of the rings and the request engine's modules,
compiled by mypyc from the very .py files mypy --strict checks (docs/design.md, "The compiled hot path").

By default each part is optional: without a C compiler (or without mypy) the install goes on, and
that part runs as Python, the slow path (fxis_shm/_compiled.py says so at import).
FXIS_REQUIRE_COMPILED=1 (release builds, `make wheels`) turns that off: a part that fails to build
fails the build. FXIS_PURE_PYTHON=1 builds no mypyc part (the ROS 2 venvs share the checkout's).
"""

import os
import runpy
import sys

from setuptools import Extension, setup

PARTS = runpy.run_path(os.path.join(os.path.dirname(os.path.abspath(__file__)), "fxis_shm", "_compiledparts.py"))
REQUIRED = os.environ.get("FXIS_REQUIRE_COMPILED") == "1"


def compiled_core() -> list:
    if os.environ.get("FXIS_PURE_PYTHON") == "1" and not REQUIRED:
        print("setup.py: FXIS_PURE_PYTHON=1, the request engine stays Python", file=sys.stderr)
        return []
    files = [PARTS["module_path"](m) for m in PARTS["MYPYC_MODULES"]]
    try:
        from mypyc.build import mypycify

        extensions = mypycify(files, opt_level="3", group_name=PARTS["GROUP"])
    except (Exception, SystemExit) as exc:  # no mypy, or it failed: the .py files serve (slow path)
        if REQUIRED:
            raise SystemExit(f"setup.py: FXIS_REQUIRE_COMPILED=1 and mypyc failed: {exc!r}") from exc
        print(f"setup.py: the request engine stays Python (mypyc: {exc!r})", file=sys.stderr)
        return []
    for extension in extensions:
        extension.optional = not REQUIRED  # no C compiler: the .py files serve
    return extensions


def c_helpers() -> list:
    return [
        Extension(name, list(sources), depends=list(headers), optional=not REQUIRED)
        for name, (sources, headers) in PARTS["C_EXTENSIONS"].items()
    ]


setup(ext_modules=[*c_helpers(), *compiled_core()])
