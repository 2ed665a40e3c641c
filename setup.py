"""Builds the compiled parts; everything else is in pyproject.toml. Each is optional: without a C
compiler (or without mypy) the install goes on, and that part runs as Python, the slow path
(fxis_shm/_compiled.py says so at import; docs/design.md, "The compiled hot path").

- fxis_shm/shm/_ordered.c: the ring's memory-ordering helper (without it, rings work on x86-64 only);
- fxis_shm/shm/_slotio.c: the ring reader's seqlock reads (snapshot records, copy, check);
- fxis_shm/shm/_fastpick.c with fxis_shm/core/pickcore.c: the same-host read of the common requests
  (image, tuple with `at`, latest) in one call: look, decide (pickcore, the C twin of the engine's
  decision), copy;
- the request engine's modules (fxis_shm/_compiled.py, MODULES), compiled by mypyc from the very
  .py files mypy --strict checks, into one group library fxis_shm/core/_hot__mypyc.
"""

import os
import sys

from setuptools import Extension, setup

HOT = [
    "fxis_shm/core/timesearch.py",
    "fxis_shm/core/snapshot.py",
    "fxis_shm/core/selection.py",
    "fxis_shm/core/waitpolicy.py",
    "fxis_shm/core/sequences.py",
    "fxis_shm/core/decisions.py",
    "fxis_shm/core/engine.py",
]


def compiled_core() -> list:
    if os.environ.get("FXIS_PURE_PYTHON") == "1":
        print("setup.py: FXIS_PURE_PYTHON=1, the request engine stays Python", file=sys.stderr)
        return []
    try:
        from mypyc.build import mypycify

        extensions = mypycify(HOT, opt_level="3", group_name="fxis_shm.core._hot")
    except (Exception, SystemExit) as exc:  # no mypy, or it failed: the .py files serve (slow path)
        print(f"setup.py: the request engine stays Python (mypyc: {exc!r})", file=sys.stderr)
        return []
    for extension in extensions:
        extension.optional = True  # no C compiler: the .py files serve
    return extensions


setup(
    ext_modules=[
        Extension("fxis_shm.shm._ordered", ["fxis_shm/shm/_ordered.c"], optional=True),
        Extension(
            "fxis_shm.shm._slotio", ["fxis_shm/shm/_slotio.c"], depends=["fxis_shm/shm/seqlock.h"], optional=True
        ),
        Extension(
            "fxis_shm.shm._fastpick",
            ["fxis_shm/shm/_fastpick.c", "fxis_shm/shm/plainpick.c", "fxis_shm/core/pickcore.c"],
            depends=["fxis_shm/shm/seqlock.h", "fxis_shm/shm/plainpick.h", "fxis_shm/core/pickcore.h"],
            optional=True,
        ),
        *compiled_core(),
    ]
)
