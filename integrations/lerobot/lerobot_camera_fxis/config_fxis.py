"""``FxisCameraConfig``: camera type ``fxis`` in a LeRobot robot's ``cameras`` dict."""

from __future__ import annotations

from dataclasses import dataclass

from lerobot.cameras.configs import CameraConfig, ColorMode, Cv2Rotation

SYNC_MODES = ("tuple", "capture")


@CameraConfig.register_subclass("fxis")
@dataclass(kw_only=True)
class FxisCameraConfig(CameraConfig):  # type: ignore[misc]
    """One camera of an fxis service (or of several: a list of endpoints is one MultiClient).

    ``camera`` is the fxis camera's name. ``width``/``height``/``fps`` are checked against the
    service at connect (None: taken from it); ``width``/``height`` are the image LeRobot gets,
    after ``rotation``. ``server_key``/``client_key``: CurveZMQ, the service's public key file
    and this client's secret key file. ``sync``: ``"tuple"`` (the joint tuple nearest each
    control tick) or ``"capture"`` (cameras that can be triggered capture at the tick plus
    ``capture_lead_ms``; in a lockstep service every tuple is a lockstep one anyway).
    ``max_skew_ms``: refuse a tuple whose skew is larger (the read raises RuntimeError).
    Every fxis camera of a robot with the same endpoints, keys and sync shares one client and
    one tuple per tick."""

    camera: str
    endpoint: list[str] | str = "tcp://127.0.0.1:5555"  # list first: draccus tries the union in order
    server_key: str | None = None
    client_key: str | None = None
    sync: str = "tuple"
    max_skew_ms: float | None = None
    capture_lead_ms: float = 50.0
    request_timeout_s: float = 2.0
    color_mode: ColorMode = ColorMode.RGB
    rotation: Cv2Rotation = Cv2Rotation.NO_ROTATION
    warmup_s: float = 1.0

    def __post_init__(self) -> None:
        self.color_mode = ColorMode(self.color_mode)
        self.rotation = Cv2Rotation(self.rotation)
        if self.sync not in SYNC_MODES:
            raise ValueError(f"`sync` is expected to be in {list(SYNC_MODES)}, but {self.sync!r} is provided.")
        if (self.server_key is None) != (self.client_key is None):
            raise ValueError("`server_key` and `client_key` go together (CurveZMQ needs both).")
        if not self.camera:
            raise ValueError("`camera` (the fxis camera's name) is required.")

    @property
    def endpoints(self) -> tuple[str, ...]:
        return (self.endpoint,) if isinstance(self.endpoint, str) else tuple(self.endpoint)
