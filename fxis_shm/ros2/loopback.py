"""Cyclone DDS settings for one host: every packet on 127.0.0.1, for a bridge and its ROS 2
nodes on one machine (and for the tests and benches). Print them for ``CYCLONEDDS_URI``::

    export CYCLONEDDS_URI="$(python -m fxis_shm.ros2.loopback)"

A cell whose nodes run on several hosts keeps Cyclone's defaults (or its own XML) instead.
"""

from __future__ import annotations

import sys


def loopback_config(
    *, max_participant_index: int = 32, trace_file: str | None = None, large_fragments: bool = True
) -> str:
    """Cyclone XML that keeps every packet on 127.0.0.1 and still lets processes find each other.

    * only ``lo`` (``NetworkInterface address=127.0.0.1``), no multicast at all: discovery goes by
      unicast to the well-known ports of participant indices 0..``max_participant_index`` on
      127.0.0.1, so each process takes a free index (``ParticipantIndex auto``);
    * ``large_fragments``: 64 kB datagrams, as loopback's MTU allows; a 1.4 MB frame is 22 of them
      instead of about 1040 with Cyclone's defaults (which a real LAN should keep);
    * a 4 MiB socket receive buffer asked for (less accepted);
    * ``trace_file``: Cyclone's configuration trace, to check which interfaces it chose.
    """
    sizes = "<MaxMessageSize>65000B</MaxMessageSize><FragmentSize>64000B</FragmentSize>" if large_fragments else ""
    tracing = ""
    if trace_file:
        tracing = f"<Tracing><Verbosity>config</Verbosity><OutputFile>{trace_file}</OutputFile></Tracing>"
    return (
        '<CycloneDDS xmlns="https://cdds.io/config"><Domain Id="any">'
        "<General>"
        '<Interfaces><NetworkInterface address="127.0.0.1" multicast="false"/></Interfaces>'
        "<AllowMulticast>false</AllowMulticast>"
        f"{sizes}"
        "</General>"
        "<Discovery>"
        "<ParticipantIndex>auto</ParticipantIndex>"
        f"<MaxAutoParticipantIndex>{max_participant_index}</MaxAutoParticipantIndex>"
        '<Peers><Peer Address="127.0.0.1"/></Peers>'
        "</Discovery>"
        '<Internal><SocketReceiveBufferSize min="default" max="4MiB"/></Internal>'
        f"{tracing}"
        "</Domain></CycloneDDS>"
    )


if __name__ == "__main__":
    sys.stdout.write(loopback_config() + "\n")
