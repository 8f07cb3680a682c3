#!/usr/bin/env python3
"""An independent ROS 2 cell for the tests, in rclpy (Fast DDS): it behaves like ros2_control's
joint_state_broadcaster + joint_trajectory_controller on a three-axis gantry.

- publishes sensor_msgs/JointState on --js-topic at --rate Hz: the three axis joints under their
  own names (not x/y/z) plus a spindle joint, in an order that is not x, y, z;
- follows trajectory_msgs/JointTrajectory from --traj-topic like joint_trajectory_controller:
  a new trajectory replaces the current one from the current state, header stamp 0 = start now,
  cubic Hermite between points when velocities are given (linear otherwise), hold after the
  last point; the joints follow the interpolated setpoint --lag seconds late;
- logs every published state (stamp ns, the three axis positions and velocities) to --log as CSV;
- plays faults after --fault-after seconds of motion and --fault-after-trajectories trajectories
  followed (both; the count makes the campaign's progress at the fault independent of the
  host's load): `missing` (joint y left out of the
  message), `nan` (joint y NaN), `stop` (no joint states for --stop-for seconds; negative:
  never again), `stuck` (joint y stops following);
- drops the first --drop-first trajectories, as a controller whose subscription matched the
  writer only after they were written does;
- with --js-after-readers N, publishes no joint state until its discovery sees N subscriptions
  on --js-topic, as a publisher that never matched the first of them does (it sends nothing to
  a reader it has not discovered);
- writes to stderr when its discovery sees trajectory writers come or go and when its
  subscription matches them (with the writers it knows on every other topic), and at the end
  how many trajectories it followed and dropped (the tests append it to their failure
  messages).

With --log-endpoints FILE it writes when its discovery first knew each endpoint of the graph
(tests/stress/endpoint_announcements.sh).

It writes --ready once its publisher and subscription exist, and ends on SIGTERM/SIGINT.
"""
import argparse
import bisect
import math
import signal
import sys
import time

import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory


def hermite(p0, v0, p1, v1, t0, t1, t):
    h = t1 - t0
    if h <= 0:
        return p1, v1
    s = min(max((t - t0) / h, 0.0), 1.0)
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    p = h00 * p0 + h10 * h * v0 + h01 * p1 + h11 * h * v1
    d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
    v = (d00 * p0 + d10 * h * v0 + d01 * p1 + d11 * h * v1) / h
    return p, v


class Trajectory:
    """Setpoints over time: knots (t, positions, velocities); hold outside them."""

    def __init__(self, t0, pos, vel):
        self.knots = [(t0, list(pos), list(vel))]
        self.cubic = True

    def at(self, t):
        ts = [k[0] for k in self.knots]
        i = bisect.bisect_right(ts, t)
        if i == 0:
            return self.knots[0][1], [0.0] * 3
        if i == len(self.knots):
            return self.knots[-1][1], [0.0] * 3
        (ta, pa, va), (tb, pb, vb) = self.knots[i - 1], self.knots[i]
        out_p, out_v = [], []
        for j in range(3):
            if self.cubic:
                p, v = hermite(pa[j], va[j], pb[j], vb[j], ta, tb, t)
            else:
                f = (t - ta) / (tb - ta)
                p, v = pa[j] + f * (pb[j] - pa[j]), (pb[j] - pa[j]) / (tb - ta)
            out_p.append(p)
            out_v.append(v)
        return out_p, out_v


class Cell(Node):
    def __init__(self, a):
        super().__init__(a.node_name)
        self.a = a
        self.joints = a.joints.split(",")
        start = [float(v) for v in a.start.split(",")]
        self.t_start = time.monotonic()
        self.traj = Trajectory(self.t_start, start, [0.0] * 3)
        self.first_motion = None
        self.stuck_y = None
        self.pub = self.create_publisher(JointState, a.js_topic, 10)
        self.sub = self.create_subscription(JointTrajectory, a.traj_topic, self.on_trajectory, 10)
        self.log = open(a.log, "w") if a.log else None
        if self.log:
            self.log.write("stamp_ns,x_m,y_m,z_m,vx_mps,vy_mps,vz_mps\n")
        self.trajectories = 0
        self.dropped = 0
        self.writers = (0, 0)
        self.fault_start = None
        self.ticks = 0
        self.released = a.js_after_readers <= 0
        self.endpoints_log = open(a.log_endpoints, "w") if a.log_endpoints else None
        self.endpoints_seen = set()
        if self.endpoints_log:
            self.endpoints_log.write("t_s,kind,topic,node,gid\n")
        self.timer = self.create_timer(1.0 / a.rate, self.tick)

    def on_trajectory(self, msg):
        now = time.monotonic()
        if self.dropped < self.a.drop_first:
            self.dropped += 1
            return
        order = [msg.joint_names.index(j) for j in self.joints]
        pos, vel = self.traj.at(now)
        t = Trajectory(now, pos, vel)
        t.cubic = all(len(p.velocities) == len(msg.joint_names) for p in msg.points)
        for p in msg.points:
            tf = p.time_from_start.sec + p.time_from_start.nanosec * 1e-9
            v = [p.velocities[k] for k in order] if t.cubic else [0.0] * 3
            t.knots.append((now + tf, [p.positions[k] for k in order], v))
        self.traj = t
        self.trajectories += 1
        if self.first_motion is None:
            self.first_motion = now

    def fault(self, now):
        a = self.a
        if a.fault == "none" or self.first_motion is None:
            return None
        if self.fault_start is None:
            if now - self.first_motion < a.fault_after or self.trajectories < a.fault_after_trajectories:
                return None
            self.fault_start = now
        if a.fault == "stop" and a.stop_for >= 0 and now - self.fault_start > a.stop_for:
            return None
        return a.fault

    def watch_writers(self, now):
        """Logs when this participant's discovery sees the trajectory writers come and go, and
        when its subscription matches them (why a trajectory was or was not received)."""
        seen = (len(self.get_publishers_info_by_topic(self.a.traj_topic)), self.sub.get_publisher_count())
        if seen != self.writers:
            self.writers = seen
            print(
                f"cell: {now - self.t_start:.2f} s: {seen[0]} writer(s) discovered on {self.a.traj_topic}, "
                f"{seen[1]} matched by the subscription; {self.trajectories + self.dropped} trajectories received; "
                f"writers discovered on the other topics: {self.writers_elsewhere()}",
                file=sys.stderr,
                flush=True,
            )

    def log_endpoints(self, now):
        """--log-endpoints: when this participant's discovery first knew each endpoint of the
        graph (a late one among its node's: an announcement lost and made again)."""
        for topic, _ in self.get_topic_names_and_types():
            for kind, infos in (("writer", self.get_publishers_info_by_topic(topic)), ("reader", self.get_subscriptions_info_by_topic(topic))):
                for info in infos:
                    gid = bytes(info.endpoint_gid).hex()
                    if (kind, gid) not in self.endpoints_seen:
                        self.endpoints_seen.add((kind, gid))
                        self.endpoints_log.write(f"{now - self.t_start:.3f},{kind},{topic},{info.node_namespace.rstrip('/')}/{info.node_name},{gid}\n")
        self.endpoints_log.flush()

    def held(self, now):
        """Whether joint states are still held back (--js-after-readers): checked every 20 ticks."""
        if self.released or self.ticks % 20:
            return not self.released
        n = len(self.get_subscriptions_info_by_topic(self.a.js_topic))
        self.released = n >= self.a.js_after_readers
        if self.released and self.a.js_after_readers > 0:
            print(f"cell: {now - self.t_start:.2f} s: {n} subscriptions on {self.a.js_topic}: joint states start", file=sys.stderr, flush=True)
        return not self.released

    def writers_elsewhere(self):
        """Writers this participant's discovery knows on every other topic: which of a
        participant's announcements it has (a trajectory writer never discovered, were the
        announcements of that participant's other writers lost with it?)."""
        topics = sorted(t for t, _ in self.get_topic_names_and_types() if t != self.a.traj_topic)
        return ", ".join(f"{t} {len(self.get_publishers_info_by_topic(t))}" for t in topics) or "none"

    def tick(self):
        now = time.monotonic()
        self.ticks += 1
        if self.ticks % 20 == 0:
            self.watch_writers(now)
            if self.endpoints_log:
                self.log_endpoints(now)
        pos, vel = self.traj.at(now - self.a.lag)
        fault = self.fault(now)
        if fault == "stop":
            return
        if self.held(now):
            return
        if fault == "stuck":
            if self.stuck_y is None:
                self.stuck_y = pos[1]
            pos[1], vel[1] = self.stuck_y, 0.0
        msg = JointState()
        msg.header.stamp = self.get_clock().now().to_msg()
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        # Not in x, y, z order, with a joint that is not an axis.
        names = [self.joints[2], "spindle", self.joints[0], self.joints[1]]
        values = [pos[2], 0.0, pos[0], pos[1]]
        speeds = [vel[2], 0.0, vel[0], vel[1]]
        if fault == "nan":
            values[3] = math.nan
        if fault == "missing":
            del names[3], values[3], speeds[3]
        msg.name, msg.position, msg.velocity = names, values, speeds
        self.pub.publish(msg)
        if self.log:
            self.log.write(f"{stamp_ns},{pos[0]!r},{pos[1]!r},{pos[2]!r},{vel[0]!r},{vel[1]!r},{vel[2]!r}\n")


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--node-name", default="gantry_cell")
    p.add_argument("--joints", default="gantry_x_joint,gantry_y_joint,quill_joint", help="joints of x,y,z")
    p.add_argument("--js-topic", default="/joint_states")
    p.add_argument("--traj-topic", default="/joint_trajectory_controller/joint_trajectory")
    p.add_argument("--rate", type=float, default=200.0)
    p.add_argument("--lag", type=float, default=0.02)
    p.add_argument("--start", default="0.5,0.4,-0.3")
    p.add_argument("--log", default="")
    p.add_argument("--ready", default="")
    p.add_argument("--fault", default="none", choices=["none", "missing", "nan", "stop", "stuck"])
    p.add_argument("--fault-after", type=float, default=0.0)
    p.add_argument("--fault-after-trajectories", type=int, default=0)
    p.add_argument("--stop-for", type=float, default=-1.0)
    p.add_argument("--drop-first", type=int, default=0)
    p.add_argument("--js-after-readers", type=int, default=0)
    p.add_argument("--log-endpoints", default="", help="CSV of when each endpoint of the graph was first discovered")
    a = p.parse_args()
    rclpy.init()
    cell = Cell(a)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    if a.ready:
        with open(a.ready, "w") as f:
            f.write("ready\n")
    while not stop:
        rclpy.spin_once(cell, timeout_sec=0.05)
    for f in (cell.log, cell.endpoints_log):
        if f:
            f.close()
    print(f"cell: {cell.trajectories} trajectories followed, {cell.dropped} dropped", file=sys.stderr)
    cell.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
