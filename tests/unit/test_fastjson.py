"""fxis_shm.wire.fastjson writes the bytes json.dumps writes and reads what json.loads reads,
with the same errors."""

import json
import math

import pytest
from hypothesis import given, settings, strategies as st

from fxis_shm.wire import fastjson

SCALARS = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**70), max_value=2**70)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text()  # any code point, lone surrogates too
)
VALUES = st.recursive(
    SCALARS, lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(), inner, max_size=5), max_leaves=30
)


def same(a, b) -> bool:
    """Equal, NaN included (NaN != NaN, but the documents agree)."""
    return json.dumps(a) == json.dumps(b)


@settings(max_examples=400)
@given(VALUES)
def test_writes_the_bytes_json_dumps_writes(value):
    assert fastjson.dumps(value) == json.dumps(value).encode()


@settings(max_examples=400)
@given(
    VALUES,
    st.sampled_from([{}, {"ensure_ascii": False}, {"indent": 2}, {"separators": (",", ":")}]),
    st.sampled_from(["", " ", "\n\t"]),
)
def test_reads_what_json_loads_reads(value, how, around):
    document = (around + json.dumps(value, **how) + around).encode()
    assert same(fastjson.loads(document), json.loads(document))


def outcome(read, data: bytes):
    try:
        return "value", json.dumps(read(data))
    except RecursionError:
        return "RecursionError", None
    except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError
        return type(exc).__name__, str(exc)


@settings(max_examples=400)
@given(
    st.binary(max_size=40)
    | st.sampled_from([b'{"a": 1}', b"[1, 2]", b"3", b'"x"', b"NaN", b"-Infinity"]).flatmap(
        lambda valid: st.tuples(st.binary(max_size=3), st.binary(max_size=3)).map(lambda c: c[0] + valid + c[1])
    )
)
def test_bytes_that_are_not_a_json_document_fail_as_json_loads_fails(data):
    assert outcome(fastjson.loads, data) == outcome(json.loads, data)


@pytest.mark.parametrize(
    "data",
    [
        "\ufeff{}".encode(),  # a UTF-8 byte order mark: json.loads reads past it
        '{"a": 1}'.encode("utf-16"),
        '{"a": [1, 2]}'.encode("utf-32-le"),
        b'{"a": 1} {"b": 2}',  # extra data
        b"",
        b'{"a": "\xff"}',  # not UTF-8
        b"[" * 100_000,  # nested too deeply
    ],
)
def test_what_json_loads_reads_differently_is_read_as_it_reads_it(data):
    assert outcome(fastjson.loads, data) == outcome(json.loads, data)


def test_what_json_cannot_hold_raises_what_json_dumps_raises():
    for value in ({"a": object()}, {"a": {1, 2}}, [b"bytes"]):
        with pytest.raises(TypeError) as ours:
            fastjson.dumps(value)
        with pytest.raises(TypeError) as theirs:
            json.dumps(value)
        assert str(ours.value) == str(theirs.value)
    circular: list = []
    circular.append(circular)
    with pytest.raises(ValueError, match="Circular reference"):
        fastjson.dumps(circular)
    assert fastjson.dumps([math.nan, math.inf]) == b"[NaN, Infinity]"
