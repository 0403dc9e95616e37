"""``polyswarm bench ros2``: the agent as a node of a ROS 2 graph, against the Zenoh path.

A player publishes a lidar stream (``BEAMS`` beams at ``RATE_HZ``, a robot driving
through a room with boxes, odometry at ``ODOM_HZ``) for ``DURATION_S`` seconds, either
into a real ROS 2 graph (rclpy, Fast DDS) where the agent is a node
(``source = "ros2-node"``), or as ROS 2 CDR over Zenoh as zenoh-bridge-ros2dds would
(``source = "ros2"``). Measured, side by side in one run:

* ``scans_processed``: the share of the stream's scans the agent mapped;
* ``cpu_beyond_slam_share``: the processor time of the agent's threads (all but the
  player's) less the time spent in SLAM, per second of stream: the share of one core
  the path costs;
* ``map_latency_p95_s`` (ROS 2 only): from the agent's map change (the map message's
  stamp) to a subscriber's receipt.
"""

from __future__ import annotations

import dataclasses
import math
import os
import threading
import time

import numpy as np

BEAMS = 720
RATE_HZ = 10.0
ODOM_HZ = 50.0
DURATION_S = 30.0
SPEED_MPS = 0.3
ROOM = np.array(  # walls of a 12 x 6 m room with two boxes (x0, y0, x1, y1)
    [
        [0, 0, 12, 0], [12, 0, 12, 6], [12, 6, 0, 6], [0, 6, 0, 0],
        [4, 2, 5, 2], [5, 2, 5, 3], [5, 3, 4, 3], [4, 3, 4, 2],
        [8, 3.5, 9, 3.5], [9, 3.5, 9, 4.5], [9, 4.5, 8, 4.5], [8, 4.5, 8, 3.5],
    ],
    dtype=float,
)  # fmt: skip
PLAYER_THREADS = ("player", "player-spin")


def _pose(t: float) -> tuple[float, float, float]:
    """The robot's pose at ``t``: along the room's middle and back."""
    span = 9.0
    d = (SPEED_MPS * t) % (2 * span)
    x = 1.5 + (d if d < span else 2 * span - d)
    return x, 1.2, 0.0 if d < span else math.pi


def _ranges(pose) -> np.ndarray:
    from polyswarm.raycast import cast_rays

    a = -math.pi + np.arange(BEAMS) * (2 * math.pi / BEAMS)
    r = cast_rays(pose[:2], a + pose[2], ROOM[:, :2], ROOM[:, 2:], 12.0)
    return np.where(np.isfinite(r), r, np.inf)


def _thread_cpu_s(names: tuple[str, ...]) -> tuple[float, float]:
    """(processor seconds of this process's threads named in ``names``, of all others)."""
    tick = os.sysconf("SC_CLK_TCK")
    mine = other = 0.0
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                stat = f.read()
            with open(f"/proc/self/task/{tid}/comm") as f:
                name = f.read().strip()
        except OSError:  # the thread ended
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        s = (int(fields[11]) + int(fields[12])) / tick
        if name in names:
            mine += s
        else:
            other += s
    return mine, other


def run_path(source: str, duration_s: float = DURATION_S) -> dict:
    """The stream through one path (``ros2-node`` or ``ros2``), the agent in this process."""
    from agents.agent_node import run_agent
    from agents.session import SessionSpec, open_session
    from polyswarm.config import AgentIoConfig, Config, with_overrides
    from polyswarm.runners.children import free_port
    from polyswarm.slam.scan import LaserScan
    from protocols import ros

    domain = 150 + os.getpid() % 50
    io = AgentIoConfig(source=source, output="none", namespace="bench", domain_id=domain)
    cfg = with_overrides(Config(), {"sim": {"lidar": {"out_of_range": "inf"}}})
    cfg = dataclasses.replace(cfg, agent=io)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    stop, result, latencies = threading.Event(), {}, []
    sent = 0

    with open_session(SessionSpec.router(endpoint)) as session:
        ros_player = _RosPlayer(domain, latencies) if source == "ros2-node" else None
        agent_thread = threading.Thread(
            target=lambda: result.update(
                agent=run_agent("r1", cfg, _pose(0.0), SessionSpec.client(endpoint), stop)
            ),
            name="agent",
        )
        agent_thread.start()
        if ros_player is not None:
            ros_player.wait_for_agent()
        else:
            time.sleep(2.0)
        cpu0 = _thread_cpu_s(PLAYER_THREADS)[1]

        def play() -> None:
            nonlocal sent
            t0 = time.monotonic()
            k_odom = 0
            for k in range(int(duration_s * RATE_HZ)):
                t = k / RATE_HZ
                while time.monotonic() - t0 < t:
                    time.sleep(0.001)
                while k_odom / ODOM_HZ <= t + 0.05:
                    to = k_odom / ODOM_HZ
                    if ros_player is not None:
                        ros_player.odom(to, _pose(to))
                    else:
                        session.put(
                            "bench/odom", ros.encode_odometry(to, _pose(to), SPEED_MPS, 0.0)
                        )
                    k_odom += 1
                s = LaserScan(_ranges(_pose(t)), -math.pi, 2 * math.pi / BEAMS, 0.1, 12.0, t)
                if ros_player is not None:
                    ros_player.scan(s)
                else:
                    session.put("bench/scan", ros.encode_laserscan(s))
                sent += 1

        player = threading.Thread(target=play, name="player")
        player.start()
        player.join()
        time.sleep(2.0)  # the last scans
        cpu1 = _thread_cpu_s(PLAYER_THREADS)[1]
        stop.set()
        agent_thread.join(timeout=20)
        if ros_player is not None:
            ros_player.close()
    agent = result["agent"]
    slam_s = agent.stats.slam_s
    out = {
        "scans_sent": sent,
        "scans_processed": agent.stats.scans / max(sent, 1),
        "keyframes": agent.stats.keyframes,
        "slam_share": slam_s / duration_s,
        "cpu_beyond_slam_share": max(cpu1 - cpu0 - slam_s, 0.0) / duration_s,
    }
    if ros_player is not None:
        out["maps_received"] = len(latencies)
        out["map_latency_p95_s"] = float(np.percentile(latencies, 95)) if latencies else None
    return out


class _RosPlayer:
    """The robot's side of the ROS 2 graph: a node publishing the stream, and a
    subscriber of the agent's map measuring when it arrives."""

    def __init__(self, domain: int, latencies: list) -> None:
        import rclpy
        from nav_msgs.msg import OccupancyGrid
        from nav_msgs.msg import Odometry as RosOdometry
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from rclpy.qos import qos_profile_sensor_data as sensor
        from sensor_msgs.msg import LaserScan as RosLaserScan

        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=domain)
        self.node = rclpy.create_node("bench_robot", namespace="/bench", context=self.ctx)
        self.scan_pub = self.node.create_publisher(RosLaserScan, "scan", sensor)
        self.odom_pub = self.node.create_publisher(RosOdometry, "odom", 50)
        self.RosLaserScan, self.RosOdometry = RosLaserScan, RosOdometry
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )

        def on_map(m) -> None:
            stamp = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
            latencies.append(time.time() - stamp)

        self.node.create_subscription(OccupancyGrid, "map", on_map, latched)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, name="player-spin", daemon=True)
        self.thread.start()

    def wait_for_agent(self, timeout_s: float = 20.0) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not self.scan_pub.get_subscription_count():
            time.sleep(0.1)
        time.sleep(1.0)

    @staticmethod
    def _stamp(msg, t: float) -> None:
        msg.header.stamp.sec = math.floor(t)
        msg.header.stamp.nanosec = int((t - math.floor(t)) * 1e9)

    def scan(self, s) -> None:
        m = self.RosLaserScan()
        self._stamp(m, s.stamp)
        m.header.frame_id = "laser"
        m.angle_min, m.angle_increment = s.angle_min, s.angle_increment
        m.angle_max = s.angle_min + s.angle_increment * (len(s.ranges) - 1)
        m.range_min, m.range_max = s.range_min, s.range_max
        m.ranges = s.ranges.astype(np.float32).tolist()
        self.scan_pub.publish(m)

    def odom(self, t: float, pose) -> None:
        m = self.RosOdometry()
        self._stamp(m, t)
        m.pose.pose.position.x, m.pose.pose.position.y = float(pose[0]), float(pose[1])
        m.pose.pose.orientation.z = math.sin(pose[2] / 2)
        m.pose.pose.orientation.w = math.cos(pose[2] / 2)
        m.twist.twist.linear.x = SPEED_MPS
        self.odom_pub.publish(m)

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.ctx.shutdown()


def run(duration_s: float = DURATION_S) -> dict:
    """Both paths, one after the other in this process."""
    return {
        "beams": BEAMS,
        "rate_hz": RATE_HZ,
        "duration_s": duration_s,
        "paths": {p: run_path(p, duration_s) for p in ("ros2-node", "ros2")},
    }
