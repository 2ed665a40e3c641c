"""The ``fxis`` command, a module per group of commands (run, query, record, snapshot, local; options
for those that talk to a service). The top layer: may import every layer below."""

import os

# numpy's OpenBLAS starts a thread per core at import, in every fxis process: a third of a camera
# worker's start-up CPU, for linear algebra none of them does. Set before numpy is imported, and
# inherited by `fxis run`'s workers; a user's setting wins (a hook that needs BLAS threads).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from fxis_shm.cli.main import main, parser  # noqa: E402  (after the environment above)

__all__ = ["main", "parser"]
