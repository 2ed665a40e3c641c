"""Typed camera options: each backend declares its keys; values come as text
(``--camera left=synthetic:fps=30``) or as TOML values, and are checked here.

Pure: raw values in, typed values out, ConfigError naming the camera and key.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from fxis_shm.errors import ConfigError


@dataclass(frozen=True)
class Option:
    parse: Callable[[Any], Any]  # raises ValueError with a readable reason
    default: Any
    help: str


def number(
    kind: type = float, minimum: float | None = None, maximum: float | None = None, exclusive_min: bool = False
) -> Callable[[Any], Any]:
    def parse(value: Any) -> Any:
        if isinstance(value, bool):
            raise ValueError(f"expected a number, got {value!r}")
        try:
            v = kind(value)
        except (TypeError, ValueError):
            raise ValueError(f"expected {'an integer' if kind is int else 'a number'}, got {value!r}") from None
        if kind is int and isinstance(value, float) and value != v:
            raise ValueError(f"expected an integer, got {value!r}")
        if v != v or v in (float("inf"), float("-inf")):
            raise ValueError(f"expected a finite number, got {value!r}")
        if minimum is not None and (v <= minimum if exclusive_min else v < minimum):
            raise ValueError(f"must be {'>' if exclusive_min else '>='} {minimum}, got {v}")
        if maximum is not None and v > maximum:
            raise ValueError(f"must be <= {maximum}, got {v}")
        return v

    return parse


def choice(*options: str) -> Callable[[Any], str]:
    def parse(value: Any) -> str:
        if value not in options:
            raise ValueError(f"must be one of {', '.join(options)}; got {value!r}")
        return str(value)

    return parse


def boolean(value: Any) -> bool:
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text in ("1", "true", "yes", "on"):
        return True
    if text in ("0", "false", "no", "off"):
        return False
    raise ValueError(f"expected true or false, got {value!r}")


def text(value: Any) -> str:
    if not isinstance(value, (str, int)):
        raise ValueError(f"expected text, got {value!r}")
    return str(value)


def parse_options(camera: str, kind: str, schema: Mapping[str, Option], raw: Mapping[str, Any]) -> dict[str, Any]:
    """Typed options with defaults filled in; unknown keys and bad values raise ConfigError."""
    unknown = sorted(set(raw) - set(schema))
    if unknown:
        raise ConfigError(
            f"camera {camera!r}: unknown key(s) {', '.join(unknown)} for kind {kind!r}; "
            f"known keys: {', '.join(sorted(schema))}"
        )
    parsed: dict[str, Any] = {}
    for key, opt in schema.items():
        if key not in raw:
            parsed[key] = opt.default
            continue
        try:
            parsed[key] = opt.parse(raw[key])
        except ValueError as exc:
            raise ConfigError(f"camera {camera!r}: key {key!r}: {exc}") from None
    return parsed


def split_key_values(camera: str, text_: str) -> dict[str, str]:
    """``a=1,b=2`` -> {"a": "1", "b": "2"}."""
    result: dict[str, str] = {}
    for item in filter(None, (part.strip() for part in text_.split(","))):
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"camera {camera!r}: expected key=value, got {item!r}")
        result[key.strip()] = value.strip()
    return result
