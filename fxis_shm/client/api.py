"""What every client answers, declared once: ``Client(endpoint)`` (fxis_shm.client.single) and
``Client([a, b])`` (fxis_shm.client.multiclient) take their public surface from ``ClientApi``,
signatures and docs alike. The operations that take parameters are written here (those for the
frames of one moment in its base, fxis_shm.client.framerequests) and may not be
redefined (a subclass that tries is refused when its class is made), so a parameter added for
one kind of client is there for the other; each kind fills in how a request is answered
(``_answer``) and what it has of its own (status, clocks, streams)."""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Literal, overload

from fxis_shm.client import arguments, snapshot as snapshots
from fxis_shm.client.framerequests import FrameRequests
from fxis_shm.client.frames import Frame, FrameTuple, FrameView, sequence_of
from fxis_shm.client.requestkeywords import SequenceKeywords
from fxis_shm.client.requestoptions import RequestOptions
from fxis_shm.formats.videochoice import split_encoding
from fxis_shm.formats.videotracks import VideoSettings
from fxis_shm.wire import encoding as image_encoding

if TYPE_CHECKING:
    from typing_extensions import Unpack  # (typing's own from Python 3.11)

# The operations written once, here: ClientApi refuses a subclass that redefines one.
SHARED_OPERATIONS = ("image", "tuple", "latest", "sequence", "snapshot", "subscribe", "frame_times")


class ClientApi(FrameRequests):
    """The methods every client has (the frame requests are FrameRequests'); every time given or
    returned is in the caller's clock."""

    clock: Callable[[], int]
    _clock_name: str | None  # the caller's clock by name (a snapshot's metadata says it), None: a callable

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        redefined = [name for name in SHARED_OPERATIONS if name in vars(cls)]
        if redefined:
            raise TypeError(f"{cls.__name__} redefines {redefined}: they are ClientApi's, the same for every client")

    # ---- operations over a span of time (those of one moment are FrameRequests') ----

    @overload
    def sequence(
        self, kind: str, *, camera: str, copy: Literal[True] = True, **keywords: Unpack[SequenceKeywords]
    ) -> list[Frame]: ...

    @overload
    def sequence(
        self, kind: str, *, camera: str, copy: Literal[False], **keywords: Unpack[SequenceKeywords]
    ) -> list[FrameView]: ...

    @overload
    def sequence(
        self, kind: str, *, camera: None = None, copy: Literal[True] = True, **keywords: Unpack[SequenceKeywords]
    ) -> list[FrameTuple[Frame]]: ...

    @overload
    def sequence(
        self, kind: str, *, camera: None = None, copy: Literal[False], **keywords: Unpack[SequenceKeywords]
    ) -> list[FrameTuple[FrameView]]: ...

    @overload
    def sequence(
        self, kind: str, *, camera: str | None = None, copy: bool = True, **keywords: Unpack[SequenceKeywords]
    ) -> list[Frame] | list[FrameTuple[Frame]]: ...

    def sequence(
        self,
        kind: str,
        *,
        camera: str | None = None,
        cameras: list[str] | None = None,
        count: int | None = None,
        direction: str = "before",
        interval_ms: float | None = None,
        start: int | None = None,
        end: int | None = None,
        at: int | None = None,
        sync: str | None = None,
        timeout: float | None = None,
        copy: bool = True,
        encoding: str | None = None,
        quality: int | None = None,
        timeout_ms: float | None = None,
    ) -> list[Frame] | list[FrameView] | list[FrameTuple[Frame]] | list[FrameTuple[FrameView]]:
        """Several frames of one camera, or several tuples.

        Parameters
        ----------
        kind
            ``"consecutive"``: ``count`` frames ``before``, ``after`` or ``around`` t*;
            ``"interval"``: the frames nearest to t* + i * interval_ms, i = 0..count-1;
            ``"range"``: every frame captured in [start, end].
        camera
            One camera: the result is a list of Frame.
        cameras
            Several cameras (default: all): a list of FrameTuple, led by the first camera.
        count, direction, interval_ms
            As ``kind`` says (``direction``: ``"before"``, ``"after"`` or ``"around"``).
        start, end
            int ns of the caller's clock, for ``kind="range"``.
        at
            t*, int ns of the caller's clock; default: the moment of this call.
        sync, timeout, copy, encoding, quality, timeout_ms
            As for ``tuple``.

        Returns
        -------
        list
            Frames (``camera=``) or FrameTuples (``cameras=``), oldest first.

        Raises
        ------
        InvalidArgument, RequestTimeout, UnknownCamera, CameraDown, FrameTimeout, ServiceError, Overrun
            As for ``image``.
        """
        options = RequestOptions.given(timeout, copy, encoding, quality, timeout_ms)
        cameras = arguments.camera_names(cameras)
        arguments.check_numbers(timeout, at=at, start=start, end=end, count=count, interval_ms=interval_ms)
        fields: dict[str, object] = dict(camera=camera, cameras=cameras, kind=kind, count=count, direction=direction)
        fields.update(interval_ms=interval_ms, start=start, end=end, at=at, sync=sync)
        arguments.check_request("sequence", **fields)
        header, images, check = self._answer("sequence", options, **fields)
        return sequence_of(header, images, check, single=camera is not None, view=not copy)

    def snapshot(
        self,
        at: int | None = None,
        before: float = 2.0,
        after: float = 1.0,
        out: str = "snapshot",
        cameras: list[str] | None = None,
        encoding: str = image_encoding.RAW,
        quality: int | None = None,
        *,
        video: VideoSettings | None = None,
        codec: str | None = None,
        encoder: str | None = None,
        crf: int | None = None,
        preset: str | None = None,
        gop_s: float | None = None,
    ) -> dict[str, Any]:
        """Every frame captured in [at - before, at + after] into a rosbag2/MCAP bag.

        Blocks until ``at + after`` has passed: the window's past comes from the rings at once,
        its future as the frames arrive. The bag is written as ``OUT.partial`` and renamed when
        complete; its stamps are in the caller's clock.

        Parameters
        ----------
        at
            The event's moment, int ns of the caller's clock; default: now.
        before, after
            Seconds of the window before and after ``at``.
        out
            The bag's folder (it must not exist).
        cameras
            The cameras' names; default: all.
        encoding, quality
            ``"raw"``, ``"jpeg"`` (with its quality), or a video codec (``encoding="h264"`` is
            ``video=VideoSettings("h264")``).
        video
            Each camera as video: ``VideoSettings(codec, encoder, crf, preset, gop_s)``
            (fxis_shm.formats.videotracks; codec ``"h264"``, ``"h265"`` or ``"av1"``), the
            window's first frame a keyframe, with the encoder options ``fxis record --codec`` takes.
        codec, encoder, crf, preset, gop_s
            Deprecated (DeprecationWarning): the fields of ``video`` given apart.

        Returns
        -------
        dict
            ``cameras``: per camera the ``frames`` kept and the ids of any ``missing``; the
            window and the bag's path.

        Raises
        ------
        InvalidArgument
            A bad window, folder or video setting, or ``video`` given with the deprecated keywords.
        RequestTimeout, UnknownCamera, CameraDown, ServiceError
            As for ``image`` (``OUT_OF_RANGE`` when the rings no longer hold the window's start).
        """
        video = arguments.video_of(video, codec=codec, encoder=encoder, crf=crf, preset=preset, gop_s=gop_s)
        encoding, codec = split_encoding(encoding, video.codec if video is not None else None)
        if video is None and codec is not None:  # encoding="h264"
            video = VideoSettings(codec)
        owners = self._owners(arguments.camera_names(cameras))
        return snapshots.take(owners, self.clock, out, at, before, after, encoding, quality, self._clock_name, video)

    def subscribe(self, timeout: float = 2.0, queue: int = 16) -> Any:
        """A subscriber of the streams (``frames(camera)``, and joint ``tuples(rate_hz)``), every
        time in this client's clock; a context manager like the client.

        Parameters
        ----------
        timeout
            Seconds its ``receive()`` waits for a message before RequestTimeout.
        queue
            Messages kept per stream for a reader that falls behind (older ones are dropped).

        Returns
        -------
        Subscriber
            Not subscribed to anything yet (``frames``, ``tuples``, ``topic``).

        Raises
        ------
        InvalidArgument
            A ``timeout`` or ``queue`` out of its range.
        """
        arguments.check_numbers(timeout)
        return self._subscriber(timeout, arguments.check_queue(queue))

    def frame_times(self, cameras: list[str] | None = None) -> dict[str, Any]:
        """Each camera's frames without pixels (the ``frames`` op): liveness, period and a row
        per valid frame with the fields named in ``columns``, times in the clock of the camera's
        service.

        Parameters
        ----------
        cameras
            The cameras' names; default: every camera.

        Returns
        -------
        dict
            ``now``, ``columns`` and per camera ``alive``, ``reason``, ``frames`` (the rows,
            oldest first) and, if its ring exists, ``period_ns``, ``delay_ns``, ``slots`` and
            ``triggered`` (docs/protocol.md 7.5a).

        Raises
        ------
        InvalidArgument
            ``cameras`` not a list of names.
        RequestTimeout, UnknownCamera, ServiceError
            As for ``image``.
        """
        cameras = arguments.camera_names(cameras)
        arguments.check_request("frames", cameras=cameras)
        return self._frame_times(cameras)

    # ---- what each kind of client fills in ----

    @abstractmethod
    def _owners(self, cameras: list[str] | None) -> Mapping[str, snapshots.ServiceClient]:
        """The single-service client that serves each of ``cameras`` (default: all)."""

    @abstractmethod
    def _subscriber(self, timeout: float, queue: int) -> Any: ...

    @abstractmethod
    def _frame_times(self, cameras: list[str] | None) -> dict[str, Any]: ...
