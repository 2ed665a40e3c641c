"""Writing a camera's settings back into the service's config file (``fxis set --save``), so
that the next ``fxis run --config FILE`` starts with them.

The file is edited line by line inside its ``[cameras.NAME]`` table: a key already there gets
its new value on its own line, keeping the comment after it, a new key is added at the end of
the table; comments and every other line stay as they were. A whole number goes back as an
integer where the file or the user wrote one (``fps = 20``, ``fxis set ... fps=25``: ``fps =
25``, not the ``25.0`` the camera answers). The result is read back and must hold the values,
else the file is left untouched. Written whole to a temporary file, then renamed over the
original.
"""

from __future__ import annotations

import json
import os
import re
import sys
from collections.abc import Mapping
from typing import Any

from fxis_shm.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

_TABLE = re.compile(r"^\s*\[")


def toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    return json.dumps(str(value))  # a TOML basic string: JSON's escapes are TOML's


def _value_and_comment(line: str) -> tuple[str, str]:
    """A ``key = value  # comment`` line's value text and what follows it (its spacing and
    comment, or ""): the value ends at the first ``#`` before which the line reads as TOML (a
    ``#`` inside a string is no comment)."""
    rest = line.split("=", 1)[1]
    for cut in [i for i, c in enumerate(rest) if c == "#"]:
        value = rest[:cut].rstrip()
        try:
            tomllib.loads(f"x = {value}")
        except tomllib.TOMLDecodeError:
            continue
        return value.strip(), rest[len(value) :]
    return rest.strip(), ""


def _like(value: Any, *examples: Any) -> Any:
    """``value``, an integer if it is a whole float and an example of it was an integer."""
    whole = isinstance(value, float) and value.is_integer()
    if whole and any(isinstance(e, int) and not isinstance(e, bool) for e in examples):
        return int(value)
    return value


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


def save_camera_values(
    path: str, camera: str, values: Mapping[str, Any], given: Mapping[str, Any] | None = None
) -> None:
    """Set ``values`` in ``[cameras.<camera>]`` of the TOML file ``path`` (ConfigError as
    ``camera_table`` says, or if it cannot be written); ``given``: the values as the user
    typed them, whose integers stay integers."""
    lines, start = camera_table(path, camera)
    end = next((i for i in range(start + 1, len(lines)) if _TABLE.match(lines[i])), len(lines))
    while end > start + 1 and not lines[end - 1].strip():  # new keys go before the blank lines
        end -= 1
    values = dict(values)
    for key, value in values.items():
        own = re.compile(rf"^(\s*){re.escape(key)}\s*=")
        found = next((i for i in range(start + 1, end) if own.match(lines[i])), None)
        if found is None:
            values[key] = _like(value, (given or {}).get(key))
            lines.insert(end, f"{key} = {toml_value(values[key])}")
            end += 1
            continue
        before, comment = _value_and_comment(lines[found])
        try:
            was = tomllib.loads(f"x = {before}")["x"]
        except tomllib.TOMLDecodeError:  # (a multi-line value: the read back below says so)
            was = None
        values[key] = _like(value, was, (given or {}).get(key))
        indent = own.match(lines[found]).group(1)  # type: ignore[union-attr]
        lines[found] = f"{indent}{key} = {toml_value(values[key])}{comment}"
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
