#!/usr/bin/env python3
"""Independent readers of volcal bags (acceptance: rosbag2 tooling can read what we record).

For each bag directory given, decode every message twice, with two libraries that share no
code with volcal:

- rosbags (opens the rosbag2 directory through metadata.yaml, types from the bag's ros2msg
  schemas), and
- mcap-ros2-support (opens the MCAP file alone, types from the same schemas),

and print, per bag and reader, as JSON: the message count per topic, the exact sum of the
header stamps per topic (nanoseconds), and checksums of the synchronised pairs. The Rust test
compares these with volcal's own reader.
"""
import json
import math
import sys
from pathlib import Path

from mcap_ros2.reader import read_ros2_messages
from rosbags.highlevel import AnyReader

PAIR = "volcal_msgs/msg/SyncedPair"


class Tally:
    def __init__(self):
        self.counts = {}
        self.stamps = {}
        self.l_m = []
        self.pos = []
        self.broken = 0

    def add(self, topic, msgtype, msg):
        self.counts[topic] = self.counts.get(topic, 0) + 1
        h = getattr(msg, "header", None)
        if h is not None:
            ns = h.stamp.sec * 1_000_000_000 + h.stamp.nanosec
            self.stamps[topic] = self.stamps.get(topic, 0) + ns
        if msgtype == PAIR:
            self.l_m.append(msg.l_m)
            self.pos.extend(float(v) for v in msg.position_m)
            self.broken += int(bool(msg.beam_broken))

    def result(self):
        return {
            "counts": self.counts,
            "stamp_sums": {k: str(v) for k, v in self.stamps.items()},
            "pairs": {
                "n": len(self.l_m),
                "l_m_sum": math.fsum(self.l_m),
                "position_sum": math.fsum(self.pos),
                "beam_broken": self.broken,
            },
        }


def with_rosbags(bag):
    t = Tally()
    with AnyReader([bag]) as reader:
        for conn, _, raw in reader.messages():
            t.add(conn.topic, conn.msgtype, reader.deserialize(raw, conn.msgtype))
        r = t.result()
        r["metadata_count"] = reader.message_count
    return r


def with_mcap_ros2(bag):
    t = Tally()
    for f in sorted(bag.glob("*.mcap")):
        for m in read_ros2_messages(str(f), log_time_order=False):
            t.add(m.channel.topic, m.schema.name, m.ros_msg)
    return t.result()


def main():
    out = {}
    for arg in sys.argv[1:]:
        bag = Path(arg)
        out[arg] = {"rosbags": with_rosbags(bag), "mcap_ros2": with_mcap_ros2(bag)}
    json.dump(out, sys.stdout, indent=1)


if __name__ == "__main__":
    main()
