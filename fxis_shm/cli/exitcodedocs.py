"""docs/cli.md's exit-code table, generated from fxis_shm.errors.ERROR_TABLE and
fxis_shm.cli.exitcodes.MEANINGS: ``python -m fxis_shm.cli.exitcodedocs`` prints it, ``--write
docs/cli.md`` puts it between the document's markers."""

from __future__ import annotations

import sys

from fxis_shm.cli.exitcodes import MEANINGS
from fxis_shm.errors import ERROR_TABLE
from fxis_shm.wire import ranges

BEGIN = "<!-- exit codes: generated from fxis_shm/errors.py ERROR_TABLE by python -m fxis_shm.cli.exitcodedocs -->"
END = "<!-- end of the generated exit codes -->"


RANGES_BEGIN = "<!-- ranges: generated from fxis_shm/wire/ranges.py by python -m fxis_shm.cli.exitcodedocs -->"
RANGES_END = "<!-- end of the generated ranges -->"
# each range and where a user types a number of it
WHERE: list[tuple[ranges.Range, str]] = [
    (
        ranges.TIMEOUT_S,
        "`--timeout` of every command; `Client(timeout=)`, a request's `timeout=`, `subscribe(timeout=)`",
    ),
    (
        ranges.WINDOW_S,
        "`fxis snapshot --before`, `--after`; `client.snapshot(before=, after=)` (and `before` at most "
        "the longest history of the cameras' rings, their status's `history_s`; t at most that far ahead)",
    ),
    (ranges.DURATION_S, "`fxis record --seconds`, `fxis sync-report --seconds`"),
    (
        ranges.RATE_HZ,
        "`fxis record --rate`, `fxis sync-report --rate` (and `--seconds` times the rate at most "
        f"{ranges.MAX_TUPLES} tuples)",
    ),
    (ranges.FRAMES, "`fxis record --frames`"),
    (ranges.SEQUENCE_COUNT, "`client.sequence(count=)`"),
    (ranges.AT_NS, "`--at` of `grab` and `snapshot`; `at=`, `start=`, `end=` of every request"),
    (
        ranges.MILLISECONDS,
        "`fxis sync-report --threshold-ms`, `--max-p95-ms`; `max_skew_ms=`, `interval_ms=` (either sign)",
    ),
    (ranges.PERCENT, "`fxis sync-report --min-synced-pct`, `--max-dropped-pct`"),
    (ranges.JPEG_QUALITY, "`fxis record --quality`; `quality=` of a client and a request"),
    (ranges.SLOTS, "`fxis run --slots`, `slots` of the config file"),
    (ranges.HISTORY_S, "`fxis run --history`, `history` of the config file"),
    (ranges.RESTART_LIMIT, "`fxis run --restart-limit`, `restart_limit` of the config file"),
]


def ranges_table() -> str:
    """docs/cli.md's table of ranges, between its markers."""
    rows = [RANGES_BEGIN, "| range | where |", "| --- | --- |"]
    rows += [f"| {limits.words} | {where} |" for limits, where in WHERE]
    return "\n".join([*rows, RANGES_END])


def _raised_as(code: int) -> str:
    """The classes of ERROR_TABLE that end with ``code`` (wire codes in parentheses), and the rest."""
    names = [
        f"`{cls.__name__}`" + (f" (`{wire}`)" if wire else "") for cls, exit_, wire in ERROR_TABLE if exit_ == code
    ]
    others = MEANINGS[code][1]
    return "; ".join(filter(None, [", ".join(names), others])) or "-"


def markdown_table() -> str:
    """docs/cli.md's exit-code table, between its markers."""
    rows = [BEGIN, "| code | meaning | raised as | for example |", "| --- | --- | --- | --- |"]
    for code, (meaning, _, example) in MEANINGS.items():
        rows.append(f"| {code} | {meaning} | {_raised_as(code)} | {example} |")
    return "\n".join([*rows, END])


def with_table(document: str) -> str:
    """``document`` (docs/cli.md) with its generated tables replaced by the current ones."""
    for begin_marker, end_marker, table in ((BEGIN, END, markdown_table()), (RANGES_BEGIN, RANGES_END, ranges_table())):
        head, begin, rest = document.partition(begin_marker)
        _, end, tail = rest.partition(end_marker)
        if not begin or not end:
            raise ValueError(f"the document has no {begin_marker!r} ... {end_marker!r} markers")
        document = head + table + tail
    return document


if __name__ == "__main__":  # python -m fxis_shm.cli.exitcodedocs [--write docs/cli.md]
    if sys.argv[1:2] == ["--write"]:
        path = sys.argv[2]
        with open(path) as f:
            updated = with_table(f.read())
        with open(path, "w") as f:
            f.write(updated)
    else:
        print(markdown_table() + "\n\n" + ranges_table())
