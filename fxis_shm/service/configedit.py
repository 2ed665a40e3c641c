"""Writing a camera's settings back into the service's config file (``fxis set --save``), so
that the next ``fxis run --config FILE`` starts with them.

The file is edited line by line inside its ``[cameras.NAME]`` table: a key already there gets
its new value on its own line, a new key is added at the end of the table; comments and every
other line stay as they were. The result is read back and must hold the values, else the file
is left untouched. Written whole to a temporary file, then renamed over the original.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping
from typing import Any

from fxis_shm.errors import ConfigError
from fxis_shm.service.config import tomllib

_TABLE = re.compile(r"^\s*\[")


def toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    return json.dumps(str(value))  # a TOML basic string: JSON's escapes are TOML's


def camera_table(path: str, camera: str) -> tuple[list[str], int]:
    """The file's lines and where its ``[cameras.<camera>]`` table starts; ConfigError if it
    cannot be read or has no such table (the camera came from ``--camera``)."""
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except OSError as exc:
        raise ConfigError(f"cannot read {path}: {exc.strerror}") from None
    header = re.compile(rf"^\s*\[\s*cameras\s*\.\s*(\"{re.escape(camera)}\"|{re.escape(camera)})\s*\]\s*(#.*)?$")
    start = next((i for i, line in enumerate(lines) if header.match(line)), None)
    if start is None:
        raise ConfigError(
            f"{path} has no [cameras.{camera}] table to save into (was the camera given with --camera?); "
            f"add one, or put the values in its --camera flag"
        )
    return lines, start


def save_camera_values(path: str, camera: str, values: Mapping[str, Any]) -> None:
    """Set ``values`` in ``[cameras.<camera>]`` of the TOML file ``path`` (ConfigError as
    ``camera_table`` says, or if it cannot be written)."""
    lines, start = camera_table(path, camera)
    end = next((i for i in range(start + 1, len(lines)) if _TABLE.match(lines[i])), len(lines))
    while end > start + 1 and not lines[end - 1].strip():  # new keys go before the blank lines
        end -= 1
    for key, value in values.items():
        line = f"{key} = {toml_value(value)}"
        own = re.compile(rf"^\s*{re.escape(key)}\s*=")
        found = next((i for i in range(start + 1, end) if own.match(lines[i])), None)
        if found is None:
            lines.insert(end, line)
            end += 1
        else:
            lines[found] = line
    text = "\n".join(lines) + "\n"
    try:
        saved = tomllib.loads(text)["cameras"][camera]
    except (tomllib.TOMLDecodeError, KeyError) as exc:
        raise ConfigError(f"cannot save into {path}: the edited file would not read back ({exc})") from None
    wrong = {k: saved.get(k) for k, v in values.items() if saved.get(k) != v}
    if wrong:
        raise ConfigError(f"cannot save into {path}: the edited file would read {wrong} (a multi-line value?)")
    temporary = f"{path}.{os.getpid()}.tmp"
    try:
        with open(temporary, "w", encoding="utf-8") as f:
            f.write(text)
        os.chmod(temporary, os.stat(path).st_mode & 0o7777)
        os.replace(temporary, path)
    except OSError as exc:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise ConfigError(f"cannot write {path}: {exc.strerror}") from None
