"""What the bridge sets in its own Cyclone DDS configuration so that other vendors' ROS 2 nodes,
in their default configuration, match its topics (docs/ros2.md, "What the bridge sets itself").

Fast DDS 3 (rmw_fastrtps_cpp, ROS 2's default RMW) sends XTypes TypeInformation with its readers,
as our writers do (cyclonedds derives it from the IdlStructs in ``dds``). For types with sequence
members (Image, CameraInfo, CompressedImage) Cyclone rejects the TypeObjects Fast DDS sends
(``ddsi_xt_type_init_impl with invalid type object``: a PLAIN_SEQUENCE_SMALL whose try-construct
bits are both 0) and never matches, while Fast DDS believes it has. rmw_cyclonedds_cpp carries no
type information at all, so two ROS nodes match by type name only (XTypes 7.6.3.4.2); telling
Cyclone to ignore eProsima's type information gives the bridge that same rule with Fast DDS.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

EPROSIMA_VENDOR_ID = "1.15"  # DDSI-RTPS vendor id of Fast DDS (OMG's vendor id list)
CONFIG_ENV = "CYCLONEDDS_URI"

INTEROP_XML = (
    '<CycloneDDS xmlns="https://cdds.io/config"><Domain Id="any"><Compatibility>'
    f"<IgnoreTypeInformation>{EPROSIMA_VENDOR_ID}</IgnoreTypeInformation>"
    "</Compatibility></Domain></CycloneDDS>"
)


def bridge_config(environ: Mapping[str, str] = os.environ) -> str:
    """The bridge's Cyclone configuration: the user's ``CYCLONEDDS_URI`` (files or XML, as
    Cyclone reads it), then the interop settings above, which Cyclone applies last."""
    user = environ.get(CONFIG_ENV, "").strip()
    return f"{user},{INTEROP_XML}" if user else INTEROP_XML
