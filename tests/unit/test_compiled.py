"""The compiled hot path (fxis_shm._compiled): chosen at import, FXIS_PURE_PYTHON=1 forces the
Python of every compiled module, and an edited module is never served by its stale build."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import fxis_shm
from fxis_shm import _compiled

PROBE = (
    "import json, fxis_shm; from fxis_shm import _compiled; "
    "print(json.dumps({'compiled': fxis_shm.compiled, 'status': _compiled.status()}))"
)


def probe(**env: str) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", PROBE], env={**os.environ, **env}, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout)


def test_the_switch_forces_every_module_to_python():
    forced = probe(FXIS_PURE_PYTHON="1")
    assert forced["compiled"] is False and not any(forced["status"].values())


def test_compiled_says_whether_every_module_runs_compiled():
    state = _compiled.status()
    assert fxis_shm.compiled == all(state.values())
    if _compiled.PURE:
        assert not any(state.values())
    elif _compiled.stale() is None:  # built and current (`make setup`): everything runs compiled
        assert all(state.values()), state


def test_the_finder_serves_sources_only_for_the_modules_it_names():
    finder = _compiled.SourceFirst()
    core = os.path.dirname(_compiled.__file__) + "/core"
    spec = finder.find_spec("fxis_shm.core.engine", [core])
    assert spec is not None and spec.origin.endswith("engine.py")
    assert finder.find_spec("fxis_shm.core.clockmap", [core]) is None
