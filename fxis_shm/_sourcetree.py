"""``fxis_shm.workers`` from a source checkout.

The worker processes and camera backends live in the top-level ``workers/``
folder, which an install (editable or not) maps to ``fxis_shm.workers``
(pyproject.toml). Without an install, ``PYTHONPATH=<checkout>`` finds
``fxis_shm`` but not that subpackage: this finder supplies exactly that one
name, so tests, benches and ``python -m fxis_shm.cli`` run from a checkout.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import importlib.util
import os
import sys
from collections.abc import Sequence
from types import ModuleType

NAME = "fxis_shm.workers"


class CheckoutWorkers(importlib.abc.MetaPathFinder):
    def __init__(self, folder: str):
        self.folder = folder

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname != NAME:
            return None  # its submodules are found through its __path__, the folder
        return importlib.util.spec_from_file_location(
            NAME, os.path.join(self.folder, "__init__.py"), submodule_search_locations=[self.folder]
        )


def install(package_dir: str) -> None:
    """Add the finder if ``package_dir`` (fxis_shm's folder) sits in a checkout."""
    checkout = os.path.dirname(package_dir)
    folder = os.path.join(checkout, "workers")
    if not (
        os.path.isfile(os.path.join(checkout, "pyproject.toml")) and os.path.isfile(os.path.join(folder, "__init__.py"))
    ):
        return  # an install: fxis_shm/workers is a real subpackage
    if not any(isinstance(f, CheckoutWorkers) for f in sys.meta_path):
        sys.meta_path.append(CheckoutWorkers(folder))  # last: an install's own finders win
