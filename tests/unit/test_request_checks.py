"""A request is checked field by field against its op's schema; the fast path that checks only
the fields given (wire.protocol._validate) decides as the field-by-field pass in the schema's
order does: the same request, or the same first error."""

from hypothesis import given, settings, strategies as st

from fxis_shm.errors import ProtocolError
from fxis_shm.wire import protocol

VALUES = st.sampled_from(
    [None, 0, 1, -1, 7, 2**62, 1.5, True, "", "cam0", "joint", "auto", "none", "jpeg", "raw", [], ["cam0"], [1], {}]
)


def in_schema_order(header: dict) -> dict:
    """The checks as the service made them before the fast path: every field of the schema in turn."""
    op = header["op"]
    schema = protocol._REQUESTS[op]
    unknown = sorted(header.keys() - schema.keys())
    if unknown:
        raise ProtocolError(f"unknown field(s) {unknown} for op {op!r}")
    request = protocol._checked_in_order(header, schema, op)
    if op in protocol.CROSS_CHECKS:
        protocol.CROSS_CHECKS[op](request)
    return request


def outcome(check, header: dict):
    try:
        return "request", list(check(dict(header)).items())
    except ProtocolError as exc:
        return "error", exc.code, exc.message


@st.composite
def headers(draw):
    op = draw(st.sampled_from(sorted(protocol._REQUESTS)))
    fields = sorted(set(protocol._REQUESTS[op]) - {"v", "op"})  # (those two are checked before, alike)
    header = {"v": protocol.VERSION, "op": op}
    for field in draw(st.lists(st.sampled_from([*fields, "unknown_field"]), max_size=6)):
        header[field] = draw(VALUES)
    return header


@settings(max_examples=3000)
@given(headers())
def test_the_fast_check_decides_as_the_field_by_field_pass(header):
    assert outcome(lambda h: protocol._validate(h, protocol._REQUESTS), header) == outcome(in_schema_order, header)
