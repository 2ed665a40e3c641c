"""Writes docs/reference/cli.md, the `fxis` command reference, from the command's own argparse
parsers: each command's `--help`, as a user sees it. `--check` compares instead of writing (the
suite's tests/unit/test_docs_reference.py does), so the reference cannot drift from `--help`.

    python scripts/cli_reference.py [--check]
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys

OUT = pathlib.Path(__file__).resolve().parents[1] / "docs" / "reference" / "cli.md"
WIDTH = "100"  # argparse wraps help to $COLUMNS: one width, whatever terminal runs this

HEADER = """# `fxis` command reference

Generated from the command's own parsers by `scripts/cli_reference.py` (the suite fails when it
differs from `--help`): every command and option as `fxis COMMAND --help` prints them. What each
command is for: [the commands by task](../commands.md); exit codes and error lines: [cli.md](../cli.md);
the configuration file's keys: [configuration](../config.md).
"""


def render() -> str:
    os.environ["COLUMNS"] = WIDTH
    from fxis_shm.cli.main import parser

    top = parser()
    parts = [HEADER, "## `fxis`\n", "```text\n" + top.format_help().rstrip() + "\n```\n"]
    commands = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction))
    for name, command in commands.choices.items():
        parts.append(f"## `fxis {name}`\n")
        parts.append("```text\n" + command.format_help().rstrip() + "\n```\n")
    return "\n".join(parts)


def main() -> int:
    text = render()
    if "--check" in sys.argv[1:]:
        if not OUT.is_file() or OUT.read_text() != text:
            print(f"{OUT} differs from the command's --help: run python scripts/cli_reference.py", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
