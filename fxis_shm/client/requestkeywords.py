"""The keyword arguments of the client's frame requests apart from ``copy`` (and, for
``sequence``, ``camera``), as ``TypedDict``s: the overloads that type ``copy=False`` apart
(fxis_shm.client.framerequests, fxis_shm.client.api) take them as ``**Unpack[...]`` rather than
repeat each parameter list. Types only; each operation's own signature names and documents
every parameter."""

from __future__ import annotations

from typing import TypedDict


class LatestKeywords(TypedDict, total=False):
    encoding: str | None
    quality: int | None


class ImageKeywords(LatestKeywords, total=False):
    at: int | None
    wait: str | None
    timeout: float | None
    timeout_ms: float | None
    capture: bool


class TupleKeywords(ImageKeywords, total=False):
    sync: str | None
    max_skew_ms: float | None
    partial: bool


class SequenceKeywords(TypedDict, total=False):
    cameras: list[str] | None
    count: int | None
    direction: str
    interval_ms: float | None
    start: int | None
    end: int | None
    at: int | None
    sync: str | None
    timeout: float | None
    encoding: str | None
    quality: int | None
    timeout_ms: float | None
