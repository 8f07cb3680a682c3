#!/usr/bin/env python3
"""CycloneDDS subscriber of /interferometer/abscissa (wire compatibility with ROS 2).

Usage: cyclone_abscissa.py DOMAIN COUNT TIMEOUT_S

Joins DDS domain DOMAIN on the loopback interface only, subscribes to the DDS topic
`rt/interferometer/abscissa` with the DDS type `volcal_msgs::msg::dds_::Abscissa_`, i.e. ROS 2's
names for the topic /interferometer/abscissa of type volcal_msgs/msg/Abscissa, declared here
independently of volcal from the .msg definition, and prints each sample as a JSON line until
COUNT samples arrived or TIMEOUT_S passed. A first line {"ready": true} says the reader exists.
"""
import json
import struct
import sys
import time
from dataclasses import dataclass

from cyclone_loopback import Header_  # noqa: E402  (sets the loopback-only configuration first)

from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import float64, uint32, uint64  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


@dataclass
class Abscissa_(IdlStruct, typename="volcal_msgs::msg::dds_::Abscissa_"):
    header: Header_
    station: uint32
    beam: uint32
    abscissa_m: float64
    signal_strength: float64
    beam_broken: bool
    trigger_id: uint64


def bits(x):
    return struct.unpack("<Q", struct.pack("<d", x))[0]


def main():
    domain, count, timeout = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
    dp = DomainParticipant(domain)
    topic = Topic(dp, "rt/interferometer/abscissa", Abscissa_)
    qos = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(4096))
    reader = DataReader(dp, topic, qos=qos)
    print(json.dumps({"ready": True}), flush=True)
    got = 0
    end = time.time() + timeout
    while got < count and time.time() < end:
        for s in reader.take(N=256):
            print(
                json.dumps(
                    {
                        "sec": s.header.stamp.sec,
                        "nanosec": s.header.stamp.nanosec,
                        "frame_id": s.header.frame_id,
                        "station": s.station,
                        "beam": s.beam,
                        # Doubles as their IEEE 754 bits: exact, whatever the JSON parser.
                        "abscissa_m_bits": bits(s.abscissa_m),
                        "signal_strength_bits": bits(s.signal_strength),
                        "beam_broken": bool(s.beam_broken),
                        "trigger_id": s.trigger_id,
                    }
                ),
                flush=True,
            )
            got += 1
        time.sleep(0.01)
    print(json.dumps({"received": got}), flush=True)


if __name__ == "__main__":
    main()
