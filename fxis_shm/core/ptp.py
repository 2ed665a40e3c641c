"""A camera's PTP (IEEE 1588) state from its GenICam features, and whether a scheduled action
command may be sent to it. Pure: the features come in through a reader function
(workers/backends/aravis_ptp.py reads them from an Aravis camera).

Cameras name these features two ways: the SFNC's ``PtpEnable`` / ``PtpStatus`` /
``PtpOffsetFromMaster`` (newer cameras, some only after ``PtpDataSetLatch``), and GigE Vision's
``GevIEEE1588`` / ``GevIEEE1588Status`` (older ones). A clock is locked when its port state is
Slave (synchronized to a master) or Master (it is the reference others follow).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

ENABLE_FEATURES = ("PtpEnable", "GevIEEE1588")
STATUS_FEATURES = ("PtpStatus", "GevIEEE1588Status")
OFFSET_FEATURES = ("PtpOffsetFromMaster", "GevIEEE1588OffsetFromMaster")
LATCH_FEATURES = ("PtpDataSetLatch", "GevIEEE1588DataSetLatch")  # commands: latch, then read
LOCKED_STATES = frozenset({"Slave", "Master"})


@dataclass(frozen=True)
class PtpState:
    """What the camera says of its clock; None where it has no such feature."""

    enabled: bool | None = None
    status: str | None = None
    offset_ns: int | None = None

    @property
    def available(self) -> bool:
        return self.enabled is not None or self.status is not None

    @property
    def locked(self) -> bool:
        return bool(self.enabled) and self.status in LOCKED_STATES

    def why_not_locked(self) -> str | None:
        """Why a scheduled action would not fire at its time on this camera, or None."""
        if not self.available:
            return (
                "it has no PTP features (PtpEnable/PtpStatus, GevIEEE1588/GevIEEE1588Status): "
                "its clock cannot be locked"
            )
        if not self.enabled:
            return "PTP is disabled on it (PtpEnable/GevIEEE1588 is false)"
        if self.status not in LOCKED_STATES:
            return f"its PTP state is {self.status or 'unknown'}, not Slave or Master: its clock is not locked"
        return None

    def as_status(self) -> dict[str, object]:
        return {"available": self.available, "enabled": self.enabled, "status": self.status,
                "offset_ns": self.offset_ns, "locked": self.locked}  # fmt: skip


def _bool(text: str) -> bool:
    return text.strip().lower() in ("true", "1", "on")


def read_ptp(read: Callable[[str], str | None], execute: Callable[[str], bool]) -> PtpState:
    """The state from ``read(feature)`` (its value as text, None when the camera lacks it) after
    ``execute(command)`` of the first latch command the camera has (True if it had it)."""
    for latch in LATCH_FEATURES:
        if execute(latch):
            break

    def first(names: tuple[str, ...]) -> str | None:
        return next((v for v in map(read, names) if v is not None), None)

    enabled, status, offset = first(ENABLE_FEATURES), first(STATUS_FEATURES), first(OFFSET_FEATURES)
    return PtpState(
        enabled=None if enabled is None else _bool(enabled),
        status=status,
        offset_ns=None if offset is None else int(float(offset)),
    )


class ClockNotLocked(ValueError):
    """A scheduled action refused before it was sent: some camera's clock is not locked."""


def require_locked(states: dict[str, PtpState]) -> None:
    """ClockNotLocked naming each camera (by name or address) whose clock is not locked, and why."""
    reasons = [f"{name}: {why}" for name, state in states.items() if (why := state.why_not_locked())]
    if reasons:
        raise ClockNotLocked("scheduled action refused: " + "; ".join(reasons))
