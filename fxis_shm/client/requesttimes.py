"""The times of a request seen from the caller: the latest moment it names, whether the
service's clock needs estimating at all, and the same t* asked again of another path."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fxis_shm.core import timebase
from fxis_shm.core.clockmap import IDENTITY, SAME_CLOCK, SHARED, ClockEstimate
from fxis_shm.shm.localpath import boot_id, time_namespace
from fxis_shm.wire.headers import ReplyHeader


def last_needed(op: str, fields: Mapping[str, Any]) -> int | None:
    """The latest moment (caller's clock) whose frames a request asks for, if it names one."""
    if op == "sequence" and fields["kind"] == "range":
        end: int = fields["end"]
        return end
    at: int | None = fields.get("at")
    if (
        op == "sequence"
        and fields["kind"] == "interval"
        and at is not None
        and fields["count"]
        and fields["interval_ms"]
        and fields["interval_ms"] > 0
    ):
        return at + int((fields["count"] - 1) * fields["interval_ms"] * 1e6)
    return at


def fixed_mapping(caller_clock: str | None, service: dict[str, Any]) -> ClockEstimate | None:
    """The mapping when no estimate is needed: the service reads the very clock the caller
    does (same kernel, and for CLOCK_MONOTONIC the same time namespace), or both read a
    clock kept in step across hosts (realtime, tai). None: it must be estimated."""
    service_clock = timebase.of_status(service)
    if caller_clock != service_clock:
        return None
    same_kernel = service.get("boot_id") is not None and service.get("boot_id") == boot_id()
    if caller_clock == "monotonic":
        namespace = time_namespace()
        return (
            IDENTITY if same_kernel and namespace is not None and service.get("time_namespace") == namespace else None
        )
    return ClockEstimate(0, method=SAME_CLOCK if same_kernel else SHARED)


def same_moment(op: str, fields: dict[str, object], header: ReplyHeader) -> dict[str, object]:
    """The fields of a request asked again: for the t* the service chose the first time."""
    if op == "latest" or fields.get("at") is not None or header.get("t_request") is None:
        return fields
    return {**fields, "at": header["t_request"]}
