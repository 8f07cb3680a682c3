#!/usr/bin/env python3
"""An independent look at the ROS 2 graph, as `ros2 node list` / `ros2 topic list -t` give it:
an rclpy node (Fast DDS) polls the graph for --seconds and prints, as JSON, when it first saw
each node and each topic with its types (seconds from its own start), and what it saw last.

Usage: ros2_graph.py --seconds 10 [--expect-nodes a,b,c]: also when all of them were first
named together ("all_expected_at"), and whether all were still named at the end.
"""
import argparse
import json
import time

import rclpy


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--expect-nodes", default="")
    a = p.parse_args()
    expect = set(filter(None, a.expect_nodes.split(",")))
    t0 = time.monotonic()
    rclpy.init()
    node = rclpy.create_node("volcal_graph_probe")
    nodes_seen, topics_seen = {}, {}
    last_nodes, last_topics, all_at = [], [], None
    events = []  # [t, "+/name" or "-/name"] as nodes come and go
    while time.monotonic() - t0 < a.seconds:
        rclpy.spin_once(node, timeout_sec=0.1)
        now = round(time.monotonic() - t0, 3)
        names = sorted(f"{ns.rstrip('/')}/{n}" for n, ns in node.get_node_names_and_namespaces())
        events += [[now, "+" + n] for n in sorted(set(names) - set(last_nodes))]
        events += [[now, "-" + n] for n in sorted(set(last_nodes) - set(names))]
        last_nodes = names
        last_topics = sorted((t, sorted(types)) for t, types in node.get_topic_names_and_types())
        for n in last_nodes:
            nodes_seen.setdefault(n, now)
        for t, types in last_topics:
            topics_seen.setdefault(t, {"t": now, "types": types})
        if expect and all_at is None and expect <= {n.rsplit("/", 1)[-1] for n in last_nodes}:
            all_at = now
    print(json.dumps({"nodes_first_seen": nodes_seen, "topics_first_seen": topics_seen,
                      "nodes_last": last_nodes, "all_expected_at": all_at, "events": events,
                      "topics_last": last_topics, "elapsed": round(time.monotonic() - t0, 3)}))
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
