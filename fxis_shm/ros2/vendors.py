"""What the bridge sets in its own Cyclone DDS configuration so that other vendors' ROS 2 nodes,
in their default configuration, match its topics (docs/ros2.md, "What the bridge sets itself").

Fast DDS 3 (rmw_fastrtps_cpp, ROS 2's default RMW) sends XTypes TypeInformation with its readers,
as our writers do (cyclonedds derives it from the IdlStructs in ``dds``). For types with sequence
members (Image, CameraInfo, CompressedImage) Cyclone rejects the TypeObjects Fast DDS sends
(``ddsi_xt_type_init_impl with invalid type object``: a PLAIN_SEQUENCE_SMALL whose try-construct
bits are both 0) and never matches, while Fast DDS believes it has. rmw_cyclonedds_cpp carries no
type information at all, so two ROS nodes match by type name only (XTypes 7.6.3.4.2); telling
Cyclone to ignore eProsima's type information gives the bridge that same rule with Fast DDS.

Fast DDS keeps the kernel's default receive buffer (212,992 bytes), and Cyclone sends a sample's
fragments in one burst: a 300 kB frame overran it every time, and a reliable reader got its frames
only as fast as repairs came (8-15 of 20 frames/s at 640x480, with gaps). Cyclone can send a part
of a sample at first and the rest as the reader asks for it (``BurstSize/MaxInitTransmit``, a
percentage of the reader's receive buffer, presumed where the reader does not say) and bound each
resend (``MaxRexmit``): with 25 % and 64 kB, a default Fast DDS node got 20.0 frames/s of each of
two 640x480 cameras with no gaps (tests/integration/test_ros2.py). Cyclone readers announce their
buffer, so to them the first burst stays as large as before.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, MutableMapping

EPROSIMA_VENDOR_ID = "1.15"  # DDSI-RTPS vendor id of Fast DDS (OMG's vendor id list)
# The bridge's own Fast DDS transports on the rclpy path (FASTDDS_BUILTIN_TRANSPORTS, read by Fast DDS
# >= 2.13 when the participant is made): its shared-memory segment holds each sample until every
# reader on the host has taken it, and with the default size (512 kB) a reader that stopped reading
# made the writer reuse buffers another reader had not read yet: that reader lost frames (1 run in
# 3 of test_ros2's stopped-reader test; 0 in 6 with 16 MB). 64 MB holds 10 frames of history of 4
# cameras of 1360x1024 bgr8.
FASTDDS_TRANSPORTS_ENV = "FASTDDS_BUILTIN_TRANSPORTS"
FASTDDS_TRANSPORTS = "DEFAULT?sockets_size=64MB"
# DDSI-RTPS vendor id of Fast DDS (OMG's vendor id list)
CONFIG_ENV = "CYCLONEDDS_URI"

FIRST_BURST_PERCENT = 25  # of a reader's receive buffer, sent at once when a sample is written
RESEND_BURST = "64kB"  # resent at once in answer to one NACK

INTEROP_XML = (
    '<CycloneDDS xmlns="https://cdds.io/config"><Domain Id="any">'
    f"<Compatibility><IgnoreTypeInformation>{EPROSIMA_VENDOR_ID}</IgnoreTypeInformation></Compatibility>"
    f"<Internal><BurstSize><MaxInitTransmit>{FIRST_BURST_PERCENT}</MaxInitTransmit>"
    f"<MaxRexmit>{RESEND_BURST}</MaxRexmit></BurstSize></Internal>"
    "</Domain></CycloneDDS>"
)


def bridge_config(environ: Mapping[str, str] = os.environ) -> str:
    """The bridge's Cyclone configuration: the user's ``CYCLONEDDS_URI`` (files or XML, as
    Cyclone reads it), then the interop settings above, which Cyclone applies last."""
    user = environ.get(CONFIG_ENV, "").strip()
    return f"{user},{INTEROP_XML}" if user else INTEROP_XML


def use_fastdds_transports(environ: MutableMapping[str, str] = os.environ) -> None:
    """Set the bridge's Fast DDS transports (above) unless the user chose theirs; for its own
    process only, before rclpy makes the participant. Other RMWs do not read the variable."""
    environ.setdefault(FASTDDS_TRANSPORTS_ENV, FASTDDS_TRANSPORTS)
