"""What the CycloneDDS checkers share: a loopback-only participant configuration (set before
cyclonedds is imported) and the ROS 2 standard types every volcal message starts with."""
import os
from dataclasses import dataclass

# Loopback only: no multicast; discover the other participants by unicast on 127.0.0.1.
os.environ["CYCLONEDDS_URI"] = (
    "<CycloneDDS><Domain id='any'><General>"
    "<Interfaces><NetworkInterface address='127.0.0.1'/></Interfaces>"
    "<AllowMulticast>false</AllowMulticast></General>"
    "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
    "<MaxAutoParticipantIndex>40</MaxAutoParticipantIndex>"
    "<Peers><Peer address='127.0.0.1'/></Peers></Discovery>"
    "</Domain></CycloneDDS>"
)

from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import int32, uint32  # noqa: E402


@dataclass
class Time_(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header_(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time_
    frame_id: str
