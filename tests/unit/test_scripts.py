"""What the scripts and the Makefile rely on exists (issue 37): every module the Python they
embed (``python -c '...'``, and the ``-c`` strings that Python hands to a child) imports, and
every file of the tree they name. scripts/test-aarch64.sh runs on an emulated CPU only by hand,
so an import its Python kept after a module moved went unnoticed until then."""

import ast
import importlib
import importlib.util
import re
from pathlib import Path

import pytest

TREE = Path(__file__).resolve().parents[2]
FILES = sorted(TREE.glob("scripts/*.sh")) + [TREE / "Makefile"]
_SNIPPETS = re.compile(r"""python3?\s+-c\s+(?:'([^']*)'|"((?:[^"\\]|\\.)*)")""")
_TREE_PATHS = re.compile(r"(?<![\w/.*$-])((?:tests|bench|scripts|fxis_shm|workers)/[\w/.-]*\.(?:py|sh|c|h))\b")


def embedded_python(text: str) -> list[str]:
    """The code of every ``python -c`` in a shell script or Makefile."""
    return [
        single if single else double.replace('\\"', '"').replace("$$", "$")
        for single, double in _SNIPPETS.findall(text)
    ]


def imports_of(code: str) -> list[tuple[str, str | None]]:
    """(module, name imported from it or None) for each import of ``code`` and of the ``-c``
    strings it passes to a child interpreter (``[sys.executable, "-c", "..."]``)."""
    found: list[tuple[str, str | None]] = []
    for node in ast.walk(ast.parse(code)):
        if isinstance(node, ast.Import):
            found += [(alias.name, None) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            found += [(node.module, alias.name) for alias in node.names]
        elif isinstance(node, (ast.List, ast.Tuple)):
            values = [e.value if isinstance(e, ast.Constant) else None for e in node.elts]
            found += [imp for flag, child in zip(values, values[1:]) if flag == "-c" for imp in imports_of(child)]
    return found


def missing_imports(code: str) -> list[str]:
    missing = []
    for module, name in imports_of(code):
        if importlib.util.find_spec(module) is None:
            missing.append(module)
        elif name is not None and not hasattr(importlib.import_module(module), name):
            if importlib.util.find_spec(f"{module}.{name}") is None:
                missing.append(f"{module}.{name}")
    return missing


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_every_module_the_embedded_python_imports_exists(path):
    snippets = embedded_python(path.read_text())
    assert [m for code in snippets for m in missing_imports(code)] == []


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_every_file_of_the_tree_named_exists(path):
    named = set(_TREE_PATHS.findall(path.read_text()))
    assert sorted(n for n in named if not (TREE / n).exists()) == []


def test_the_aarch64_script_embeds_python_and_names_its_tests():
    text = (TREE / "scripts/test-aarch64.sh").read_text()
    assert len(embedded_python(text)) >= 1
    assert {"tests/unit/test_slotio.py", "tests/integration/test_compiledread.py"} <= set(_TREE_PATHS.findall(text))


def test_the_check_finds_the_import_that_rotted():
    """The script's Python before the fix: the module had moved to fxis_shm.shm.ordering."""
    rotten = """python -c '
import subprocess, sys
from fxis_shm.shm import ordering
subprocess.run([sys.executable, "-c", "from fxis_shm import ordering; print(ordering.MODE)"])'"""
    assert [m for code in embedded_python(rotten) for m in missing_imports(code)] == ["fxis_shm.ordering"]
    assert _TREE_PATHS.findall("TESTS=(tests/unit/test_gone.py)") == ["tests/unit/test_gone.py"]
