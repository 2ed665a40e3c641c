"""Which of the hot path's modules run compiled, and the switch that forces them all to Python.

The install compiles the request engine's modules (``MODULES``, the pure core: mypyc builds
each .py into an extension module beside it, setup.py), the ring reader's seqlock reads
(``fxis_shm.shm._slotio``, C) and the compiled read of the common requests
(``fxis_shm.shm._fastpick``, C, with its decision's C twin; fxis_shm.shm.fastpick). Python
imports an extension module before the .py of the same name, so the compiled code is chosen at
import when it is there; the .py files stay the one source of the engine. Without a C compiler
at install time nothing is compiled, and everything runs as Python, the slow path (``fxis run``
says so, and a client on the service's host, once); FXIS_PURE_PYTHON=1 turns the C readers off too.

FXIS_PURE_PYTHON=1 in the environment forces the Python of every module here (the
finder below puts each .py before its extension module), for tests and measurements. The
same finder serves the .py files when the compiled group is missing or older than one of
them (a module edited since the last build: `make setup` or `pip install -e .` rebuilds).
``check()`` (``fxis_shm.compiled``) is True when every one of them runs compiled.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import importlib.util
import logging
import os
import sys
from collections.abc import Sequence
from types import ModuleType

from fxis_shm import _compiledparts

PURE = os.environ.get("FXIS_PURE_PYTHON") == "1"
GROUP = _compiledparts.GROUP + "__mypyc"  # mypyc's library of the compiled modules (setup.py)
MODULES = _compiledparts.MYPYC_MODULES  # the modules of one request's decision, leaves first
C_HELPERS = ("fxis_shm.shm._slotio", "fxis_shm.shm._fastpick")  # the C readers of the rings


class SourceFirst(importlib.abc.MetaPathFinder):
    """Finds the modules of ``MODULES`` as their .py files, never as extension modules."""

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname not in MODULES or not path:
            return None
        for folder in path:
            source = os.path.join(folder, fullname.rpartition(".")[2] + ".py")
            if os.path.isfile(source):
                return importlib.util.spec_from_file_location(fullname, source)
        return None


def stale() -> str | None:
    """Why the compiled modules cannot serve (None: they can): not built, or older than a .py."""
    spec = importlib.util.find_spec(GROUP)
    if spec is None or not spec.origin:
        return "not built"
    folder = os.path.dirname(spec.origin)
    if not os.path.isfile(os.path.join(folder, "..", "..", "pyproject.toml")):
        return None  # an install (a wheel's files carry no build times): only a checkout is edited
    built = os.path.getmtime(spec.origin)
    newer = [m for m in MODULES if os.path.getmtime(os.path.join(folder, m.rpartition(".")[2] + ".py")) > built]
    return f"{', '.join(newer)} changed since the build" if newer else None


def install() -> None:
    global _why_source
    if PURE:
        _why_source = "FXIS_PURE_PYTHON=1"
    else:
        _why_source = stale()
    if _why_source and not any(isinstance(f, SourceFirst) for f in sys.meta_path):
        sys.meta_path.insert(0, SourceFirst())


_why_source: str | None = None


def is_compiled(module: ModuleType) -> bool:
    return not (getattr(module, "__file__", None) or "").endswith(".py")


def status() -> dict[str, bool]:
    """Each module of the hot path (imported now): True if it runs compiled."""
    import importlib

    from fxis_shm.shm import fastpick, slotio

    modules = {name: is_compiled(importlib.import_module(name)) for name in MODULES}
    return {**modules, C_HELPERS[0]: slotio.IMPL == "c", C_HELPERS[1]: fastpick.AVAILABLE}


def check() -> bool:
    """True if the whole hot path runs compiled."""
    return all(status().values())


def slow_path_line() -> str:
    """What running the slow path means and how to leave it, said by ``fxis run`` and once by a
    client on the service's host (``warn_slow_path``): where the hot path runs, not everywhere."""
    state = status()
    return (
        f"fxis-shm runs its hot path as Python, the slow path (not compiled: "
        f"{', '.join(name for name, done in state.items() if not done)}{f'; {_why_source}' if _why_source else ''}): "
        "reinstall with a C compiler present (pip install -e . builds it)"
    )


def slow_unasked() -> bool:
    """True if the hot path runs as Python though FXIS_PURE_PYTHON=1 did not ask for it."""
    return not PURE and not check()


_warned = False


def warn_slow_path() -> None:
    """Logs ``slow_path_line`` once per process on the slow path not asked for."""
    global _warned
    if not _warned and slow_unasked():
        _warned = True
        logging.getLogger("fxis_shm").warning("%s", slow_path_line())


install()  # on import, before any module it names is imported (fxis_shm/__init__.py imports it first)
