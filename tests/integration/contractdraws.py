"""What the contract generator (test_contract_generator.py) draws: the values a user can type,
at and beyond their ranges (fxis_shm.wire.ranges), and the commands built of them.

A drawn value that is valid and would make a command wait long (a --timeout of an hour at an
endpoint that never answers, a snapshot --after of 50 minutes) is replaced by a short one: the
draws test what a command does with its input, not how long a legitimate wait lasts."""

from __future__ import annotations

import math

from hypothesis import strategies as st

SERVICE = "<the shared service>"  # replaced by the shared service's endpoint when a case runs
CAMERA = "a"  # the shared service's camera
NOWHERE = "tcp://127.0.0.1:9"  # discard: nothing answers there (a well-formed endpoint no service has)
TMP = "{tmp}"  # the case's own folder


def _text(max_size: int = 24) -> st.SearchStrategy[str]:
    """Text as argv can carry it (no NUL)."""
    return st.text(st.characters(blacklist_characters="\0", blacklist_categories=("Cs",)), max_size=max_size)


EDGES = ["nan", "NaN", "inf", "-inf", "1e309", "-1", "0", "-0", "0.0", "1e-320", "5e-324", "1e9", "1e18", "1.5e18"]
EDGES += ["9223372036854775807", "9223372036854775808", "4611686018427387905", "3600", "3600.0001", "604800"]
EDGES += ["604801", "1000", "1000.5", "100", "101", "1", "2", "1_000", "0x10", "", " ", "abc", "٣", "1e", "--1"]


def typed_numbers() -> st.SearchStrategy[str]:
    """A number as typed: edges of every range, any integer or float, or no number at all."""
    return st.one_of(
        st.sampled_from(EDGES),
        st.integers(-(10**20), 10**20).map(str),
        st.floats(allow_nan=True, allow_infinity=True).map(repr),
        _text(12),
    )


def _value(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def short(limit: float, numbers: st.SearchStrategy[str] | None = None) -> st.SearchStrategy[str]:
    """``numbers`` (default: typed_numbers) with a valid value above ``limit`` made ``limit``: a
    long, legitimate wait is not what the generator tests."""

    def shortened(text: str) -> str:
        value = _value(text)
        return str(limit) if value is not None and value > limit else text

    return (typed_numbers() if numbers is None else numbers).map(shortened)


ODD_ENDPOINTS = [
    "tcp://[::1]:5555",
    "tcp://[::1]:0",
    "tcp://::1:5555",
    "tcp://[::]:5555",
    "tcp://[fe80::1%eth0]:5555",
    "tcp://ip6-localhost:5555",
    "ipc://",
    "ipc:///tmp/" + "x" * 120,
    "ipc://" + "/é" * 60,
    "tcp://127.0.0.1:65536",
    "tcp://127.0.0.1:-1",
    "tcp://127.0.0.1:0",
    "tcp://127.0.0.1",
    "tcp://:5555",
    "tcp://*:5555",
    "tcp://0.0.0.0:5555",
    "tcp://no-such-host.invalid:5555",
    "tcp://héllo:5555",
    "tcp://" + "a" * 300 + ":5555",
    "udp://127.0.0.1:5555",
    "127.0.0.1:5555",
    "",
    "tcp://127.0.0.1:5555x",
    "tcp://127.0.0.1: 5555",
]


def endpoints() -> st.SearchStrategy[str]:
    """The shared service, nowhere, or an endpoint of a wrong or odd form (never a well-formed
    one of another port: another engineer's service may listen there)."""
    return st.one_of(st.just(SERVICE), st.just(NOWHERE), st.sampled_from(ODD_ENDPOINTS), _text(30))


def names() -> st.SearchStrategy[str]:
    """A camera's or a service's name: ours, unicode, over-long, empty, with a slash."""
    odd = ["", " ", "/", "..", "a/b", "a" * 300, "ü" * 40, "a,b", "a b", "-x", "left", "zz"]
    return st.one_of(st.just(CAMERA), st.sampled_from(odd), _text(40))


def outs() -> st.SearchStrategy[str]:
    """An --out folder: new, existing and full, unwritable, odd or over-long names."""
    odd = [f"{TMP}/new", f"{TMP}/full", f"{TMP}/no/such/x", "/proc/x", f"{TMP}/" + "d" * 300, f"{TMP}/é ü", "", "/"]
    return st.one_of(st.sampled_from(odd), _text(20).map(lambda n: f"{TMP}/{n}"))


def cameras_flag() -> st.SearchStrategy[list[str]]:
    return st.one_of(st.just([]), st.lists(names(), max_size=3).map(lambda ns: ["--cameras", ",".join(ns)]))


def flag(name: str, values: st.SearchStrategy[str]) -> st.SearchStrategy[list[str]]:
    """``[name, value]`` or nothing."""
    return st.one_of(st.just([]), values.map(lambda v: [name, v]))


def client_flags() -> st.SearchStrategy[list[str]]:
    """--endpoint and --timeout (valid timeouts short; one always where nothing answers)."""

    def flags(endpoint: str, timeout: str | None) -> list[str]:
        if timeout is None and endpoint != SERVICE:
            timeout = "0.2"
        return ["--endpoint", endpoint, *(["--timeout", timeout] if timeout is not None else [])]

    return st.builds(flags, endpoints(), st.one_of(st.none(), short(0.3)))


def joined(*parts: st.SearchStrategy[list[str]]) -> st.SearchStrategy[list[str]]:
    return st.tuples(*parts).map(lambda lists: [item for part in lists for item in part])


SETTING_KEYS = ["exposure_us", "gain", "width", "height", "fps", "foo", "", "gäin", "x" * 100, "history"]


def assignments() -> st.SearchStrategy[list[str]]:
    """KEY=VALUE of ``fxis set``: known and unknown keys, any typed value, no '=' at all."""
    pair = st.tuples(st.one_of(st.sampled_from(SETTING_KEYS), _text(10)), typed_numbers())
    return st.lists(st.one_of(pair.map(lambda kv: f"{kv[0]}={kv[1]}"), _text(10)), min_size=1, max_size=3)


VIDEO = joined(
    flag("--codec", st.sampled_from(["h264", "h265", "av1", "mpeg2", ""])),
    flag("--crf", typed_numbers()),
    flag("--gop", typed_numbers()),
)

# each command the generator runs in this process: its argv after the command's name
COMMANDS: dict[str, st.SearchStrategy[list[str]]] = {
    "status": joined(client_flags(), st.sampled_from([[], ["--json"]])),
    "grab": joined(client_flags(), outs().map(lambda o: ["--out", o]), cameras_flag(), flag("--at", typed_numbers())),
    "snapshot": joined(
        client_flags(),
        outs().map(lambda o: ["--out", o]),
        flag("--before", typed_numbers()),
        st.one_of(short(0.3), st.just("0.1")).map(lambda v: ["--after", v]),
        flag("--at", typed_numbers()),
        cameras_flag(),
        st.one_of(st.just([]), VIDEO),
    ),
    "record": joined(
        client_flags(),
        outs().map(lambda o: ["--out", o]),
        st.one_of(
            short(0.3).map(lambda v: ["--seconds", v]),
            st.tuples(short(3), short(50, st.sampled_from(["50", "1e9", "nan", "-1", "0"]))).map(
                lambda fr: ["--frames", fr[0], "--rate", fr[1]]
            ),
        ),
        flag("--quality", typed_numbers()),
        flag("--encoding", st.sampled_from(["raw", "jpeg", "h264", "png", ""])),
        cameras_flag(),
    ),
    "get": joined(client_flags(), names().map(lambda n: [n]), st.lists(_text(10), max_size=2)),
    "set": joined(client_flags(), names().map(lambda n: [n]), assignments()),
    "sync-report": joined(
        client_flags(),
        st.one_of(short(0.3), st.just("0.2")).map(lambda v: ["--seconds", v]),
        flag("--rate", typed_numbers()),
        flag("--threshold-ms", typed_numbers()),
        flag("--max-p95-ms", typed_numbers()),
        flag("--min-synced-pct", typed_numbers()),
        flag("--max-dropped-pct", typed_numbers()),
        cameras_flag(),
    ),
    "export": joined(
        st.sampled_from([[f"{TMP}/no-bag"], [f"{TMP}/full"], ["/proc/self"], [""]]),
        flag("--camera", names()),
        outs().map(lambda o: ["--out", o]),
    ),
    "keys": joined(outs().map(lambda o: ["--out", o]), flag("--name", names())),
    "clean": flag("--name", names().map(lambda n: n if n in ("", "/", "..") else f"ctr{n}")),
}
