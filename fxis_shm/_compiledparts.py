"""The one list of fxis-shm's compiled parts, read by setup.py (what to build), the Makefile (what
a rebuild depends on), ``fxis_shm._compiled`` (what must run compiled) and the docs.

Plain constants and no imports, so that setup.py can read this file before the package is built
(``runpy.run_path``) and ``python fxis_shm/_compiledparts.py`` can list the sources for make.
"""

# The request engine's modules, compiled by mypyc from the very .py files mypy --strict checks,
# into one group library (GROUP); leaves first.
MYPYC_MODULES = (
    "fxis_shm.core.timesearch",
    "fxis_shm.core.snapshot",
    "fxis_shm.core.selection",
    "fxis_shm.core.waitpolicy",
    "fxis_shm.core.sequences",
    "fxis_shm.core.decisions",
    "fxis_shm.core.requeststate",
    "fxis_shm.core.engine",
)
GROUP = "fxis_shm.core._hot"  # mypyc names the shared library GROUP + "__mypyc"

# The C extensions: module name -> (sources, headers they include).
C_EXTENSIONS = {
    # the ring's memory-ordering helper (without it, rings work on x86-64 only)
    "fxis_shm.shm._ordered": (("fxis_shm/shm/_ordered.c",), ()),
    # the ring reader's seqlock reads (snapshot records, copy, check)
    "fxis_shm.shm._slotio": (("fxis_shm/shm/_slotio.c",), ("fxis_shm/shm/seqlock.h",)),
    # the same-host read of the common requests in one call, with pickcore, the engine's C twin
    "fxis_shm.shm._fastpick": (
        ("fxis_shm/shm/_fastpick.c", "fxis_shm/shm/plainpick.c", "fxis_shm/core/pickcore.c"),
        ("fxis_shm/shm/seqlock.h", "fxis_shm/shm/plainpick.h", "fxis_shm/core/pickcore.h"),
    ),
}


def module_path(module: str) -> str:
    """The .py file of a module named in MYPYC_MODULES, relative to the checkout."""
    return module.replace(".", "/") + ".py"


def sources() -> list[str]:
    """Every file a build of the compiled parts reads, relative to the checkout."""
    files = [module_path(m) for m in MYPYC_MODULES]
    for c_files, headers in C_EXTENSIONS.values():
        files += [f for f in (*c_files, *headers) if f not in files]
    return files


if __name__ == "__main__":
    print(" ".join(sources()))
