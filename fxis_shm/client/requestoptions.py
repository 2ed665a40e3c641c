"""How a frame request is answered, apart from which frames it asks for: one value that the
client's operations hand to every path that answers them (the compiled read, one service, or
several), instead of four parameters passed apart."""

from __future__ import annotations

import warnings
from dataclasses import dataclass


@dataclass(frozen=True)
class RequestOptions:
    """``timeout``: seconds the service may wait for frames (None: its setting); ``copy``: False
    for read-only views of the ring slots (local path only); ``encoding`` and ``quality``: how
    the pixels travel for this request (None: the client's setting)."""

    timeout: float | None = None
    copy: bool = True
    encoding: str | None = None
    quality: int | None = None

    @classmethod
    def given(
        cls,
        timeout: float | None,
        copy: bool,
        encoding: str | None,
        quality: int | None,
        timeout_ms: float | None = None,
    ) -> RequestOptions:
        """The options a public call was given. ``timeout_ms``, the old name of ``timeout`` in ms,
        still works but warns (DeprecationWarning, pointing at the caller of the client's
        operation); ``timeout`` wins when both are given."""
        if timeout_ms is not None:
            warnings.warn("timeout_ms= is deprecated: give timeout= in seconds", DeprecationWarning, stacklevel=3)
            if timeout is None:
                timeout = timeout_ms / 1000
        return cls(timeout, copy, encoding, quality)

    @property
    def plain(self) -> bool:
        """True when only ``copy`` is given: what the compiled read answers as the service would."""
        return self.timeout is None and self.encoding is None and self.quality is None

    @property
    def timeout_ms(self) -> float | None:
        """``timeout`` as the wire's ``timeout_ms``."""
        return None if self.timeout is None else self.timeout * 1000
