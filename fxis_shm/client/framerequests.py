"""The requests for the frames of one moment, t*, that every client answers, written once
(``ClientApi``, fxis_shm.client.api, takes them with its requests over a span of time):
``image``, ``tuple`` and ``latest``, each typed apart for ``copy=False``, which answers
FrameViews (their images views of the ring slots, valid while ``still_valid()``) where the
default answers copied Frames. Each kind of client fills in how a request is answered
(``_answer``) and may have a compiled read (``_fast``)."""

from __future__ import annotations

from abc import abstractmethod
from typing import TYPE_CHECKING, Any, Literal, TypeVar, overload

from fxis_shm.client import arguments
from fxis_shm.client.fastreads import FastReads
from fxis_shm.client.frames import Answer, Frame, FrameTuple, FrameView, frames_of, tuple_of
from fxis_shm.client.requestkeywords import ImageKeywords, LatestKeywords, TupleKeywords
from fxis_shm.client.requestoptions import RequestOptions
from fxis_shm.client.serviceapi import ServiceApi

if TYPE_CHECKING:  # (typing's own from Python 3.11)
    from typing_extensions import Unpack

_Answered = TypeVar("_Answered")  # what the compiled read answered (a Frame or a FrameTuple)


class FrameRequests(ServiceApi):
    """The requests of every client for the frames of one moment; every time given or returned
    is in the caller's clock."""

    # A compiled read of the common requests, where a client has one (a single service's rings
    # read here, fxis_shm.client.fastreads): tried first, ``_compiled`` gives its answer or None.
    _fast: FastReads | None = None

    if TYPE_CHECKING:  # (fxis_shm.client.requestpaths has it, for the clients with a ``_fast``)

        def _compiled(self, answer: _Answered | None) -> _Answered | None: ...

    # ``copy=False`` answers a FrameView (its image a view of the ring slot: check still_valid())
    @overload
    def image(self, camera: str, *, copy: Literal[True] = True, **keywords: Unpack[ImageKeywords]) -> Frame: ...

    @overload
    def image(self, camera: str, *, copy: Literal[False], **keywords: Unpack[ImageKeywords]) -> FrameView: ...

    @overload
    def image(self, camera: str, *, copy: bool = True, **keywords: Unpack[ImageKeywords]) -> Frame: ...

    def image(
        self,
        camera: str,
        *,
        at: int | None = None,
        wait: str | None = None,
        timeout: float | None = None,
        copy: bool = True,
        encoding: str | None = None,
        quality: int | None = None,
        timeout_ms: float | None = None,
        capture: bool = False,
    ) -> Frame:
        """The frame of ``camera`` nearest to ``at``.

        Parameters
        ----------
        camera
            The camera's name.
        at
            t*, int ns of the caller's clock; default: the moment of this call.
        wait
            ``"auto"`` (wait only when a closer frame is about to arrive), ``"next"`` (always a
            new frame) or ``"none"``; default: the service's setting.
        timeout
            Seconds the service may wait for frames (default: its setting).
        copy
            False: a FrameView, whose image (local path) is a read-only view of the ring slot,
            with no copy at all; check ``frame.still_valid()`` after using it.
        encoding, quality
            ``"raw"``, ``"jpeg"`` or ``"png"`` and the JPEG quality, for this request only.
        timeout_ms
            The same as ``timeout``, in ms (deprecated: give ``timeout``).
        capture
            True with ``at`` in the future: a camera that can be triggered captures at ``at``
            (its frame says ``capture == "scheduled"``, ``t_target`` and ``residual_ns``); one
            that cannot answers with its frame nearest ``at`` (``"free"``).

        Returns
        -------
        Frame
            The image as a NumPy array with its metadata, times in the caller's clock (a
            FrameView with ``copy=False``).

        Raises
        ------
        InvalidArgument
            An argument out of its range or of the wrong type.
        RequestTimeout
            No reply within the client's ``timeout`` (the client stays usable).
        UnknownCamera
            A camera the service does not have.
        CameraDown
            A camera whose worker is down (see ``partial`` where offered).
        FrameTimeout
            The frames waited for did not arrive within ``timeout``.
        ServiceError
            Any other refusal, with its ``code`` (``OUT_OF_RANGE``: history the rings no longer
            hold, or a t* too far ahead; ``BUSY``: too many waiting requests).
        Overrun
            The ring came round during every copy: ask for newer frames or keep more history.
        """
        options = RequestOptions.given(timeout, copy, encoding, quality, timeout_ms)
        camera = arguments.camera_name(camera)
        if at is not None or timeout is not None:
            arguments.check_numbers(timeout, at=at)
        if self._fast is not None and not capture and options.plain:
            frame = self._compiled(self._fast.image(camera, at, wait, copy))
            if frame is not None:
                return frame
        fields: dict[str, object] = {"camera": camera, "at": at, "wait": wait, "capture": capture or None}
        arguments.check_request("image", **fields)
        return frames_of(*self._answer("image", options, **fields), view=not copy)[0]

    @overload
    def tuple(
        self, cameras: list[str] | None = None, *, copy: Literal[True] = True, **keywords: Unpack[TupleKeywords]
    ) -> FrameTuple[Frame]: ...

    @overload
    def tuple(
        self, cameras: list[str] | None = None, *, copy: Literal[False], **keywords: Unpack[TupleKeywords]
    ) -> FrameTuple[FrameView]: ...

    @overload
    def tuple(
        self, cameras: list[str] | None = None, *, copy: bool = True, **keywords: Unpack[TupleKeywords]
    ) -> FrameTuple[Frame]: ...

    def tuple(
        self,
        cameras: list[str] | None = None,
        *,
        at: int | None = None,
        sync: str | None = None,
        wait: str | None = None,
        max_skew_ms: float | None = None,
        timeout: float | None = None,
        partial: bool = False,
        copy: bool = True,
        encoding: str | None = None,
        quality: int | None = None,
        timeout_ms: float | None = None,
        capture: bool = False,
    ) -> FrameTuple[Frame]:
        """One frame per camera, nearest to ``at`` and to each other.

        Parameters
        ----------
        cameras
            The cameras' names; default: every camera of the service (or services).
        at
            t*, int ns of the caller's clock; default: the moment of this call.
        sync
            ``"joint"`` (the frames chosen together for the least skew) or ``"independent"``
            (each camera's nearest frame, the paper's search); default: the service's setting.
        wait
            As for ``image``.
        max_skew_ms
            Refuse a tuple whose skew (max minus min capture time) is larger (SkewExceeded,
            naming the best skew there was).
        timeout
            Seconds the service may wait for frames (default: its setting).
        partial
            True: cameras that are down are left out (``.missing`` names them) instead of
            failing the request with CameraDown.
        copy, encoding, quality, timeout_ms
            As for ``image``.
        capture
            True with ``at`` in the future: every camera that can be triggered captures at
            ``at`` (as for ``image``), on every service of the client.

        Returns
        -------
        FrameTuple
            Camera name to Frame, with ``skew_ns``, ``t_request`` and ``timing``.

        Raises
        ------
        InvalidArgument, RequestTimeout, UnknownCamera, CameraDown, FrameTimeout, ServiceError, Overrun
            As for ``image``.
        SkewExceeded
            With ``max_skew_ms``: no tuple near t* was that well synchronized.
        """
        options = RequestOptions.given(timeout, copy, encoding, quality, timeout_ms)
        cameras = arguments.camera_names(cameras)
        if at is not None or timeout is not None or max_skew_ms is not None:
            arguments.check_numbers(timeout, at=at, max_skew_ms=max_skew_ms)
        if self._fast is not None and not capture and options.plain and max_skew_ms is None:
            tuple_ = self._compiled(self._fast.tuple(cameras, at, sync, wait, copy))
            if tuple_ is not None:
                return tuple_
        fields: dict[str, object] = dict(cameras=cameras, at=at, sync=sync, wait=wait, max_skew_ms=max_skew_ms)
        fields.update(partial=partial or None, capture=capture or None)
        arguments.check_request("tuple", **fields)
        return tuple_of(*self._answer("tuple", options, **fields), view=not copy)

    @overload
    def latest(
        self, cameras: list[str] | None = None, *, copy: Literal[True] = True, **keywords: Unpack[LatestKeywords]
    ) -> FrameTuple[Frame]: ...

    @overload
    def latest(
        self, cameras: list[str] | None = None, *, copy: Literal[False], **keywords: Unpack[LatestKeywords]
    ) -> FrameTuple[FrameView]: ...

    @overload
    def latest(
        self, cameras: list[str] | None = None, *, copy: bool = True, **keywords: Unpack[LatestKeywords]
    ) -> FrameTuple[Frame]: ...

    def latest(
        self,
        cameras: list[str] | None = None,
        *,
        copy: bool = True,
        encoding: str | None = None,
        quality: int | None = None,
    ) -> FrameTuple[Frame]:
        """The newest stored frame of each camera, without waiting.

        Parameters
        ----------
        cameras
            The cameras' names; default: every camera.
        copy, encoding, quality
            As for ``image``.

        Returns
        -------
        FrameTuple
            Camera name to its newest Frame (not chosen together: the skew is whatever it is).

        Raises
        ------
        RequestTimeout, UnknownCamera, CameraDown, ServiceError
            As for ``image``; ``NO_FRAMES`` (a ServiceError) while a camera has stored none.
        """
        options = RequestOptions(None, copy, encoding, quality)
        cameras = arguments.camera_names(cameras)
        if self._fast is not None and options.plain:
            tuple_ = self._compiled(self._fast.latest(cameras, copy))
            if tuple_ is not None:
                return tuple_
        arguments.check_request("latest", cameras=cameras)
        return tuple_of(*self._answer("latest", options, cameras=cameras), view=not copy)

    @abstractmethod
    def _answer(self, op: str, options: RequestOptions, **fields: Any) -> Answer:
        """A frame request's reply header (times in the caller's clock), images and validity check."""
