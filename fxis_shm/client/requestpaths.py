"""How a frame request of the client travels (``SingleClient`` takes these methods): answered
here by the compiled read of the rings (fxis_shm.client.fastreads), or here by the client's own
run of the engine over the rings (fxis_shm.client.localreads), or by the service with where the
frames are in the rings (the client copies them: fxis_shm.shm.localpath), or over the network.
The path a reply took is counted in ``paths`` and named by ``Frame.path``."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, TypeVar

from fxis_shm import _compiled
from fxis_shm.client.clocktracker import ClockTracker
from fxis_shm.client.fastreads import FastReads
from fxis_shm.client.frames import LOCAL, NETWORK, Answer, Images, Validity
from fxis_shm.client.localreads import LocalReads
from fxis_shm.client.requesttimes import same_moment
from fxis_shm.core.clockmap import ClockEstimate
from fxis_shm.errors import CameraDown, LocalPathUnavailable, Overwritten, UnknownCamera
from fxis_shm.shm import fastpick
from fxis_shm.shm.localpath import LocalRings, LocalUnavailable
from fxis_shm.wire import protocol
from fxis_shm.wire.headers import ReplyHeader

_LOCAL_ATTEMPTS = 3  # requests re-asked after a torn local copy before giving up
_LOCAL_RETRY_S = 10.0  # after the rings could not be opened, the network path this long
_Answered = TypeVar("_Answered")  # what the compiled read answered (a Frame or a FrameTuple)


class RequestPaths:
    """The paths of a frame request, for a client of one service (its state is the client's)."""

    # the client's state these paths read and keep (SingleClient makes it)
    local: str  # "auto", "off" or "require"
    timeout: float
    paths: dict[str, int]  # replies by path, local copies found torn, compiled replies
    _boot_id: str | None
    _rings: LocalRings
    _reads: LocalReads | None
    _fast: FastReads | None
    _reads_off: tuple[str, float] | None
    _local_off: tuple[str, float] | None
    _tracker: ClockTracker | None
    _mapping: ClockEstimate | None

    if TYPE_CHECKING:  # the client's own (SingleClient's), used here

        def _call(self, op: str, extra_wait: float, **fields: object) -> tuple[ReplyHeader, Images]: ...
        def status(self) -> dict[str, Any]: ...
        def clock_estimate(self) -> ClockEstimate: ...
        @property
        def local_unavailable(self) -> str | None: ...

    def _fetch(self, op: str, extra_wait: float, copy: bool, **fields: object) -> Answer:
        """A request for frames, over the local path if it can be used: the reply header,
        the images (the header's ``path`` set) and a validity check for zero-copy views.
        Where the rings can be read with the service's own clock, the client answers
        itself (fxis_shm.client.localreads); otherwise the coordinator chooses the frames."""
        reads = self._local_reads()
        if reads is not None and reads.serves(op, fields):
            return self._read_locally(op, extra_wait, copy, fields)
        # a capture at T is asked once: asked again (a local reply whose rings are not here) its T has passed
        if self._local_usable() and not fields.get("capture"):
            for _ in range(_LOCAL_ATTEMPTS):
                header, images = self._call(op, extra_wait, local=self._boot_id, **fields)
                if header.get("delivery") != protocol.LOCAL:  # the service is on another kernel
                    self._give_up_local("the service runs on another kernel")
                    return self._network_reply(header, images)
                try:
                    images = self._rings.images(header["frames"], copy)
                except Overwritten:  # we were too slow: the ring came round; ask again
                    self.paths["torn"] += 1
                    continue
                except LocalUnavailable as exc:  # the frames are there, just not here: same t*
                    self._give_up_local(str(exc))
                    fields = same_moment(op, fields, header)
                    break
                self.paths[LOCAL] += 1
                self._local_off = None  # (again) usable
                header["path"] = LOCAL
                check: Validity | None = (
                    None if copy else (lambda metas=header["frames"]: all(map(self._rings.still_valid, metas)))
                )
                return header, images, check
            else:
                raise Overwritten(
                    f"the frames of {op!r} were overwritten in the rings {_LOCAL_ATTEMPTS} "
                    "times before this client could copy them (is it starved of CPU, "
                    "or are the rings too short?)"
                )
        if self.local == "require":
            raise LocalPathUnavailable(f"the local fast path cannot be used: {self.local_unavailable}")
        return self._network_reply(*self._call(op, extra_wait, **fields))

    def _read_locally(self, op: str, extra_wait: float, copy: bool, fields: dict[str, object]) -> Answer:
        reads = self._reads
        assert reads is not None  # (the caller found it so)
        deadline = reads.now() + int((self.timeout + extra_wait) * 1e9)
        try:
            header, images, check = self._answer_locally(op, fields, deadline, copy)
        except (CameraDown, UnknownCamera):
            # The service may have been restarted with new rings or other cameras: learn them again, once.
            self._drop_reads()
            if self._local_reads() is None:
                raise
            header, images, check = self._answer_locally(op, fields, deadline, copy)
        self.paths[LOCAL] += 1
        header["path"] = LOCAL
        if self._fast is None:  # the rings (re)opened: the compiled read can serve again
            self._fast = self._fast_reads()
        return header, images, check

    def _answer_locally(self, op: str, fields: dict[str, object], deadline: int, copy: bool) -> Answer:
        reads = self._reads
        assert reads is not None  # (asked again only once found again)
        torn = reads.torn
        try:
            return reads.answer(op, fields, deadline, copy)
        finally:  # the copies it found torn (and made again) count as those of the other local path
            self.paths["torn"] += reads.torn - torn

    def _local_reads(self) -> LocalReads | None:
        """The client's own reads of the rings, learnt from the service's status once."""
        if self.local == "off":
            return None
        if self._reads is not None:
            return self._reads
        if self._reads_off is not None and time.monotonic() - self._reads_off[1] < _LOCAL_RETRY_S:
            return None
        try:
            self._reads = LocalReads(self.status(), self._boot_id)
            self._reads_off = None
            _compiled.warn_slow_path()  # the request engine runs here too, not only in the service
        except LocalUnavailable as exc:
            self._reads_off = (str(exc), time.monotonic())
        self._fast = self._fast_reads()
        return self._reads

    def _fast_reads(self) -> FastReads | None:
        """The compiled read over the rings read here, if built and the caller's clock is the
        service's (it takes and returns the service's times as they are). Asked again after
        every local read while there is none, so the cheap refusals come first."""
        if self._reads is None or not fastpick.AVAILABLE or self._tracker is not None:
            return None  # (a tracked caller's clock is never the service's as it is)
        mapping = self.clock_estimate()
        if self._mapping is None or mapping.offset_ns != 0 or mapping.drift_ppm != 0:
            return None
        return self._reads.fast_reads()

    def _compiled(self, answer: _Answered | None) -> _Answered | None:
        """``answer`` of the compiled read, counted; None (it left the request to the engine) as it
        is, dropping the read once a ring was replaced (made again when the engine reopened it)."""
        if answer is None:
            fast = self._fast
            assert fast is not None  # (it gave the answer)
            self.paths["torn"] += fast.torn_since()
            if fast.retired:
                self._fast = None
        else:
            self.paths[LOCAL] += 1
            self.paths["compiled"] += 1
        return answer

    def _drop_reads(self) -> None:
        self._fast = None  # before the rings close: it holds their mappings
        if self._reads is not None:
            self._reads.close()
            self._reads = None

    def _network_reply(self, header: ReplyHeader, images: Images) -> Answer:
        self.paths[NETWORK] += 1
        header["path"] = NETWORK
        return header, images, None

    def _local_usable(self) -> bool:
        if self.local == "off":
            return False
        if self._boot_id is None:
            self._local_off = ("this kernel has no boot id to compare", time.monotonic())
            return False
        if self._local_off is not None and time.monotonic() - self._local_off[1] < _LOCAL_RETRY_S:
            return False
        return True

    def _give_up_local(self, reason: str) -> None:
        """Take the network path for a while: the rings cannot be read here now."""
        self._local_off = (reason, time.monotonic())
        if self.local == "require":
            raise LocalPathUnavailable(f"the local fast path cannot be used: {reason}")
