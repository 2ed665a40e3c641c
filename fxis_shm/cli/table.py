"""Rows of text as columns, for the commands that print tables."""

from __future__ import annotations


def aligned(rows: list[list[str]]) -> list[str]:
    """Each row as one line, its cells left-aligned in columns two spaces apart."""
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    return ["  ".join(v.ljust(w) for v, w in zip(row, widths)).rstrip() for row in rows]
