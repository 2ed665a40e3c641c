"""The checks of a request header's fields (docs/protocol.md section 5): each takes the field's
name and its value as JSON gave it, and returns the value or raises ``ProtocolError`` saying
what is wrong with it. The schemas of the codec (fxis_shm.wire.protocol) are made of these."""

from __future__ import annotations

import math
from collections.abc import Callable, Collection
from typing import NoReturn

from fxis_shm.errors import ProtocolError

# A field's check: (field name, value as decoded from JSON) -> the value. The value is whatever
# JSON held (``object``); each check narrows it, so what it returns is the field's own type.
Check = Callable[[str, object], object]

INT64_MAX = 2**63 - 1
MAX_TIMEOUT_MS = 3_600_000.0  # one hour: longer waits are surely a mistake
MAX_SETTINGS = 64  # keys in one settings request


def fail(field: str, what: str) -> NoReturn:
    raise ProtocolError(f"field {field!r} {what}")


def integer(field: str, v: object, minimum: int | None = None) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        fail(field, f"must be an integer, got {type(v).__name__}")
    if not -INT64_MAX <= v <= INT64_MAX:
        fail(field, "must fit in a signed 64-bit integer")
    if minimum is not None and v < minimum:
        fail(field, f"must be >= {minimum}, got {v}")
    return v


def number(field: str, v: object, positive: bool = True) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or v != v:
        fail(field, f"must be a number, got {type(v).__name__}")
    if v in (math.inf, -math.inf):
        fail(field, f"must be finite, got {v}")
    if positive and v <= 0:
        fail(field, f"must be > 0, got {v}")
    return v


def timeout(field: str, v: object) -> float:
    ms = number(field, v)
    if ms > MAX_TIMEOUT_MS:
        fail(field, f"must be at most {MAX_TIMEOUT_MS:.0f} ms, got {ms}")
    return ms


def boolean(field: str, v: object) -> bool:
    if not isinstance(v, bool):
        fail(field, f"must be true or false, got {type(v).__name__}")
    return v


def count(field: str, v: object) -> int:
    return integer(field, v, minimum=1)


def nonzero(field: str, v: object) -> float:
    n = number(field, v, positive=False)
    if n == 0:
        fail(field, "must not be 0")
    return n


def topic(reserved: tuple[str, ...]) -> Check:
    """The check of a topic a client names: not one that starts as the ``reserved`` ones do."""

    def check(field: str, v: object) -> str:
        if not isinstance(v, str) or not v or len(v) > 256:
            fail(field, "must be a non-empty string of at most 256 characters")
        if v.startswith(reserved):
            fail(field, f"must not start with a reserved prefix {reserved}")
        return v

    return check


def name(field: str, v: object) -> str:
    if not isinstance(v, str) or not v:
        fail(field, "must be a non-empty string")
    return v


def names(field: str, v: object) -> list[str]:
    if not isinstance(v, list) or not v:
        fail(field, "must be a non-empty list of camera names")
    checked = [name(field, item) for item in v]
    if len(set(checked)) != len(checked):
        fail(field, "names a camera twice")
    return checked


def choice(options: Collection[str]) -> Check:
    def check(field: str, v: object) -> object:
        if v not in options:
            fail(field, f"must be one of {list(options)}, got {v!r}")
        return v

    return check


def optional(check: Check) -> Check:
    def wrapped(field: str, v: object) -> object:
        return None if v is None else check(field, v)

    return wrapped


def setting_values(field: str, v: object) -> dict[str, object]:
    if not isinstance(v, dict) or not v:
        fail(field, "must be a non-empty object of setting names and values")
    if len(v) > MAX_SETTINGS:
        fail(field, f"may set at most {MAX_SETTINGS} keys at once, got {len(v)}")
    for key, value in v.items():
        if not key or not isinstance(value, (str, int, float, bool)):
            fail(field, f"must map each setting name to a number, string or boolean, got {key!r}: {value!r}")
        if isinstance(value, float) and not math.isfinite(value):
            fail(field, f"must hold finite numbers, got {key!r}: {value!r}")
    return v


def boot_id(field: str, v: object) -> str:
    if not isinstance(v, str) or not 0 < len(v) <= 64:
        fail(field, "must be the client's boot id, a string of 1 to 64 characters")
    return v


def request_id(field: str, v: object) -> int | str:
    if isinstance(v, bool) or not isinstance(v, (int, str)):
        fail(field, "must be an integer or a string")
    return v


def quality(field: str, v: object) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 100:
        fail(field, f"must be an integer from 1 to 100, got {v!r}")
    return v
