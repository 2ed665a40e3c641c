"""Mutation testing of what changed since the last full run (docs/mutation.md, "In make test").

    python scripts/mutation_changed.py record   after `make mutation`'s mutmut run (its mutants/): fail
                                                 on a survivor docs/mutation.md does not explain, else
                                                 write docs/mutation-record.json
    python scripts/mutation_changed.py run      `make mutation-changed`: run mutmut over the mutants
                                                 the changes since that record may have let survive

The record holds a hash of every function mutmut mutates ([tool.mutmut] only_mutate) and of every
test of its test selection, which test killed each mutant (tests/mutationkillers.py wrote
mutants/killers.txt), and the mutants that survived. ``run`` then runs every mutant of a function
whose source changed (or is new), and every mutant a changed or removed test killed (a test's
hash covers its own source and its file's helpers and constants, and the local modules the file
imports); the mutants that survived the full run are not run again (their functions unchanged,
they survive still) but must still be explained. It fails if a mutant it ran survived, or a
recorded survivor is, unexplained in docs/mutation.md.
"""

from __future__ import annotations

import ast
import hashlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parent.parent
RECORD = ROOT / "docs" / "mutation-record.json"
EXPLAINED = ROOT / "docs" / "mutation.md"
MUTMUT = [str(ROOT / ".venv" / "bin" / "mutmut")]
NOT_KILLED = ("survived", "no tests", "suspicious", "skipped")


def settings() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["mutmut"]


def digest(node: ast.AST | str) -> str:
    text = node if isinstance(node, str) else ast.dump(node)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def function_hashes() -> dict[str, str]:
    """mutmut's name of each function it mutates (``module.x_name``, ``module.xǁClassǁname``) -> hash."""
    hashes = {}
    for path in settings()["only_mutate"]:
        module = path.removesuffix(".py").replace("/", ".")
        for node in ast.parse((ROOT / path).read_text()).body:
            if isinstance(node, ast.FunctionDef):
                hashes[f"{module}.x_{node.name}"] = digest(node)
            elif isinstance(node, ast.ClassDef):
                for item in node.body:
                    if isinstance(item, ast.FunctionDef):
                        hashes[f"{module}.xǁ{node.name}ǁ{item.name}"] = digest(item)
    return hashes


def test_hashes() -> dict[str, str]:
    """Each test of the selection (``file::name``) -> the hash of its source, its file's other
    top-level code (helpers, constants) and the local modules that file imports."""
    hashes = {}
    for file in settings()["pytest_add_cli_args_test_selection"]:
        tree = ast.parse((ROOT / file).read_text())
        tests = [n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name.startswith("test")]
        shared = [ast.dump(n) for n in tree.body if n not in tests]
        for node in tree.body:  # `from .helpers import ...`: a helper module beside the file
            if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
                shared.append((ROOT / file).with_name(node.module + ".py").read_text())
        context = digest("\n".join(shared))
        for test in tests:
            hashes[f"{file}::{test.name}"] = digest(context + ast.dump(test))
    return hashes


def test_key(nodeid: str) -> str:
    """A test's key: its node id without parameters (``file::name[...]`` -> ``file::name``)."""
    return nodeid.removeprefix("mutants/").split("[", 1)[0]


def statuses() -> dict[str, str]:
    out = subprocess.run([*MUTMUT, "results", "--all", "true"], cwd=ROOT, capture_output=True, text=True).stdout
    return dict(re.findall(r"^\s*(\S+__mutmut_\d+): (.+?)\s*$", out, re.M))


def explained() -> set[str]:
    return set(re.findall(r"fxis_shm\.core\.[^` ]*__mutmut_[0-9]+", EXPLAINED.read_text()))


def unexplained(survivors: list[str], what: str) -> bool:
    """Says which of ``survivors`` docs/mutation.md does not explain (with ``what`` they are), if any."""
    missing = sorted(set(survivors) - explained())
    for mutant in missing:
        print(subprocess.run([*MUTMUT, "show", mutant], cwd=ROOT, capture_output=True, text=True).stdout)
    if missing:
        print("\n".join(missing))
        print(f"{what} and docs/mutation.md does not explain them")
    return bool(missing)


def record() -> int:
    survivors = sorted(m for m, s in statuses().items() if s in NOT_KILLED)
    if unexplained(survivors, "make mutation: the mutants above survived"):
        return 1
    killed_by: dict[str, set[str]] = {}
    for line in (ROOT / "mutants" / "killers.txt").read_text().splitlines():
        mutant, nodeid = line.split(" ", 1)
        killed_by.setdefault(test_key(nodeid), set()).add(mutant)
    RECORD.write_text(
        json.dumps(
            {
                "about": "written by `make mutation` (scripts/mutation_changed.py); read by `make mutation-changed`",
                "functions": function_hashes(),
                "tests": test_hashes(),
                "killed_by": {test: sorted(mutants) for test, mutants in sorted(killed_by.items())},
                "survivors": survivors,
            },
            indent=1,
            ensure_ascii=False,
        )
        + "\n"
    )
    print(f"make mutation: {len(survivors)} surviving mutants, each explained in docs/mutation.md; recorded")
    return 0


def changes(old: dict) -> tuple[list[str], list[str]]:
    """The functions changed or new since the record, and the tests changed or removed."""
    functions = [f for f, h in function_hashes().items() if old["functions"].get(f) != h]
    now = test_hashes()
    tests = [t for t, h in old["tests"].items() if now.get(t) != h]
    return functions, tests


def run() -> int:
    old = json.loads(RECORD.read_text())
    if unexplained(old["survivors"], "make mutation-changed: the mutants above survived the last full run"):
        return 1
    functions, tests = changes(old)
    again = {m for t in tests for m in old["killed_by"].get(t, ())}
    again = sorted(m for m in again if m.split("__mutmut_")[0] not in functions)  # those run whole below
    if not functions and not again:
        print("make mutation-changed: no mutated function, nor a test that killed a mutant, changed since the full run")
        return 0
    print(f"make mutation-changed: {len(functions)} functions changed or new: {' '.join(functions) or '-'}")
    print(f"  {len(tests)} tests changed or removed, which killed {len(again)} mutants of unchanged functions")
    if os.path.exists(ROOT / "mutants"):
        subprocess.run(["rm", "-rf", str(ROOT / "mutants")], check=True)
    names = [f"{f}__mutmut_*" for f in functions] + again
    env = {**os.environ, "FXIS_PURE_PYTHON": "1"}
    command = [*MUTMUT, "run", "--max-children", "2", *names]
    done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True)
    if done.returncode != 0 and "nothing matches" not in done.stdout + done.stderr:
        print(done.stdout[-3000:], done.stderr[-3000:], sep="\n")
        return done.returncode
    ran = {m: s for m, s in statuses().items() if m in again or m.split("__mutmut_")[0] in functions}
    survivors = sorted(m for m, s in ran.items() if s in NOT_KILLED)
    checked = sum(1 for s in ran.values() if s != "not checked")
    if unexplained(survivors, "make mutation-changed: the mutants above survived"):
        return 1
    print(f"make mutation-changed: {checked} mutants run, {len(survivors)} survived, each explained (docs/mutation.md)")
    return 0


if __name__ == "__main__":
    command = sys.argv[1] if len(sys.argv) > 1 else "run"
    sys.exit(record() if command == "record" else run())
