"""The library knows camera kinds and child roles by name; only the workers
import the library, never the other way round."""

from __future__ import annotations

import ast
import importlib
import importlib.util
import pathlib

import pytest

import fxis_shm
from fxis_shm.camerakinds import DISCOVERY_MODULE, KINDS, PROCESS_OPTIONS
from fxis_shm.childspec import ROLES

LIBRARY = pathlib.Path(fxis_shm.__file__).parent


def imported_modules(path: pathlib.Path) -> set[str]:
    """Every module a file imports, relative imports made absolute."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = "fxis_shm." * (node.level > 0) + (node.module or "")
            names.update({base} | {f"{base.rstrip('.')}.{alias.name}" for alias in node.names})
    return names


@pytest.mark.parametrize("path", sorted(LIBRARY.glob("*.py")), ids=lambda p: p.name)
def test_no_library_module_imports_the_workers(path):
    workers = sorted(m for m in imported_modules(path) if m.startswith("fxis_shm.workers"))
    assert workers == [], f"{path.name} imports {workers}: start a worker by name instead"


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_each_kind_names_a_backend_that_implements_it(kind):
    module, cls = KINDS[kind].backend_path
    backend = getattr(importlib.import_module(module), cls)
    assert backend.kind == kind
    assert KINDS[kind].description and not set(KINDS[kind].options) & set(PROCESS_OPTIONS)


@pytest.mark.parametrize("module", sorted([DISCOVERY_MODULE, *(cls.MODULE for cls in ROLES.values())]))
def test_each_child_module_the_library_names_exists(module):
    assert importlib.util.find_spec(module) is not None
