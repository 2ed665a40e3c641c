"""Who may change a camera's settings, face by face: one rule (docs/security.md, issue 42).

Without ``--curve-operators`` every client that may look may change. With it, only an
operator: over ZeroMQ a key in that folder (the coordinator checks CurveZMQ's User-Id); on the
dashboard whoever sends the operator token of ``--operator-token-file`` (its own, never the
viewer token), else nobody; on ROS 2 nobody (DDS carries no key) unless ``--ros2-settings
allow``. The dashboard and the bridge connect to the coordinator with the service's own key,
an operator's, so they hold the rule themselves. The Foxglove server changes no camera.
"""

from __future__ import annotations

from dataclasses import replace

from fxis_shm.service.config import ServiceConfig
from fxis_shm.service.viewertokens import ViewerAccess, read_token_file

SETTING = "operator_token_file"


def dashboard_access(config: ServiceConfig, access: ViewerAccess) -> ViewerAccess:
    """The dashboard's ``access`` with who may change settings through it."""
    token = read_token_file(config.operator_token_file, SETTING) if config.operator_token_file else None
    return replace(access, operator_token=token, read_only=bool(config.curve_operators))


def ros2_may_change(config: ServiceConfig) -> bool:
    """Whether nodes on the bridge's NS/settings may change settings (else only read them)."""
    if config.ros2 is None:
        return False
    if config.ros2.settings is not None:
        return config.ros2.settings == "allow"
    return not config.curve_operators


def change_lines(config: ServiceConfig) -> list[str]:
    """The banner's lines saying which faces can change camera settings, and who through each."""
    changers = [
        "ZeroMQ requests (operators' keys only)" if config.curve_operators else "ZeroMQ requests (every client let in)"
    ]
    readers = []
    if config.http_url:
        if config.operator_token_file:
            changers.append("the dashboard (with the operator token)")
        elif config.curve_operators:
            readers.append("the dashboard (no --operator-token-file)")
        else:
            changers.append("the dashboard (whoever may open it)")
    if config.ros2 is not None:
        if ros2_may_change(config):
            changers.append("ROS 2 NS/settings (any node on the DDS domain)")
        else:
            readers.append("ROS 2 NS/settings (--ros2-settings allow to change)")
    lines = [f"  camera settings can be changed over {', '.join(changers)}"]
    if config.http_url and config.operator_token_file:
        link = f"{config.http_url}/#operator=<the token in {config.operator_token_file}>"
        lines.append(f"      change them on the dashboard from {link}")
    return lines + ([f"  camera settings can only be read over {', '.join(readers)}"] if readers else [])
