"""The agent as a node of a real ROS 2 graph: rclpy and Fast DDS (ROS 2 Jazzy, from PyPI).

A real rclpy node plays a shared real recording's scans and odometry into the graph;
the agent (``source = "ros2-node"``) maps it, and a real rclpy subscriber receives the
``map`` it publishes."""

from __future__ import annotations

import dataclasses
import math
import random
import time

import numpy as np
from nav_msgs.msg import OccupancyGrid
from nav_msgs.msg import Odometry as RosOdometry
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan as RosLaserScan
from visualization_msgs.msg import MarkerArray

from polyswarm.config import AgentIoConfig, Config
from polyswarm.evaluation.maps import map_iou
from polyswarm.grids.convert import polymap_to_grid
from polyswarm.runners.slam import run_bag
from protocols.bags import read_bag
from tests.conftest import agent_on_a_thread, rclpy_node


def _time(msg, t: float) -> None:
    msg.header.stamp.sec = math.floor(t)
    msg.header.stamp.nanosec = int((t - math.floor(t)) * 1e9)


def _scan_msg(s, frame: str) -> RosLaserScan:
    m = RosLaserScan()
    _time(m, s.stamp)
    m.header.frame_id = frame
    m.angle_min, m.angle_increment = float(s.angle_min), float(s.angle_increment)
    m.angle_max = float(s.angle_min + s.angle_increment * (len(s.ranges) - 1))
    m.range_min, m.range_max = float(s.range_min), float(s.range_max)
    m.time_increment, m.scan_time = float(s.time_increment), float(s.scan_time)
    m.ranges = [float(r) for r in s.ranges]
    return m


def _odom_msg(t, x, y, yaw, v=0.0, w=0.0) -> RosOdometry:
    """A driver's odometry: the pose, and the velocities (base frame) it moves at."""
    m = RosOdometry()
    m.twist.twist.linear.x, m.twist.twist.angular.z = float(v), float(w)
    _time(m, t)
    m.header.frame_id, m.child_frame_id = "odom", "base_link"
    m.pose.pose.position.x, m.pose.pose.position.y = float(x), float(y)
    m.pose.pose.orientation.z, m.pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return m


def _wait_for_agent(player, scan_pub, odom_pub, name: str) -> set[str]:
    """The graph's node names once ``name`` is among them and both topics are matched
    (at most 20 s)."""
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline:
        nodes = {f"{ns.rstrip('/')}/{n}" for n, ns in player.get_node_names_and_namespaces()}
        matched = scan_pub.get_subscription_count() and odom_pub.get_subscription_count()
        if name in nodes and matched:
            break
        time.sleep(0.2)
    return nodes


def _play(bag, scan_pub, odom_pub) -> None:
    """The recording's odometry and scans into the graph, in stamp order, at 20 Hz."""
    o = bag.odometry
    dt = np.maximum(np.diff(o[:, 0]), 1e-3)
    yaw = np.unwrap(o[:, 3])
    v = np.hypot(*np.diff(o[:, 1:3], axis=0).T) / dt
    velocity = np.vstack([np.c_[v, np.diff(yaw) / dt], [0.0, 0.0]])
    time.sleep(1.0)  # both ends of the scan topic matched before the first sweep
    k_odom = 0
    for s in bag.scans:
        end = s.stamp + s.time_increment * (len(s.ranges) - 1)
        while k_odom < len(bag.odometry) and bag.odometry[k_odom, 0] <= end + 0.05:
            odom_pub.publish(_odom_msg(*bag.odometry[k_odom], *velocity[k_odom]))
            k_odom += 1
        scan_pub.publish(_scan_msg(s, bag.scan_frame))
        time.sleep(0.05)  # 20 Hz: four times the recording's rate


def _until_quiet(maps: list) -> None:
    """Wait until no map has come for 5 s (the agent has worked off its queue; at most
    90 s)."""
    quiet_since, seen = time.monotonic(), len(maps)
    deadline = time.monotonic() + 90.0
    while time.monotonic() - quiet_since < 5.0 and time.monotonic() < deadline:
        time.sleep(0.2)  # the agent works off its queue: maps keep coming
        if len(maps) != seen:
            quiet_since, seen = time.monotonic(), len(maps)


def test_a_real_recording_played_into_ros2_is_mapped_by_the_agent_node(shared_data):
    path = shared_data / "bags" / "neato-square.bag"
    bag = read_bag(path)
    offline, used = run_bag(path, Config())  # what `polyswarm slam` makes of it
    domain = random.randint(1, 200)  # a DDS domain of this test's own
    io = AgentIoConfig(source="ros2-node", output="none", namespace="neato", domain_id=domain)
    cfg = dataclasses.replace(used, agent=io)

    maps: list[tuple[float, OccupancyGrid]] = []
    robots: list[MarkerArray] = []
    latched = QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    with rclpy_node(domain, "recording_player", "/neato") as player:
        scan_pub = player.create_publisher(RosLaserScan, "scan", qos_profile_sensor_data)
        odom_pub = player.create_publisher(RosOdometry, "odom", 50)
        player.create_subscription(
            OccupancyGrid, "map", lambda m: maps.append((time.monotonic(), m)), latched
        )
        player.create_subscription(MarkerArray, "polyswarm/robots", robots.append, 10)
        with agent_on_a_thread("r1", cfg, offline.odometry[0]) as result:
            nodes = _wait_for_agent(player, scan_pub, odom_pub, "/neato/polyswarm_agent_r1")
            assert "/neato/polyswarm_agent_r1" in nodes, nodes  # as `ros2 node list` shows it
            _play(bag, scan_pub, odom_pub)
            _until_quiet(maps)
    agent = result["agent"]
    assert agent.stats.scans >= 0.95 * len(bag.scans) and agent.stats.refused == 0
    # the map `polyswarm slam` makes of the recording offline
    iou = map_iou(agent.slam.map.explored_region(), offline.map.explored_region())
    # measured 1.0 in three runs alone, 0.983 under the whole suite's load (before the
    # input rounding: 0.963 every time); the bound is the one this test had before
    assert iou >= 0.95, iou
    # the last map received is the agent's map, cell for cell at 5 cm
    assert maps, "no map reached the subscriber"
    got = maps[-1][1]
    grid = polymap_to_grid(agent.planning_map, 0.05)
    assert got.header.frame_id == "map" and abs(got.info.resolution - 0.05) < 1e-6  # float32
    assert (got.info.height, got.info.width) == grid.shape
    assert (got.info.origin.position.x, got.info.origin.position.y) == grid.origin
    assert np.array_equal(np.array(got.data, dtype=np.int8).reshape(grid.shape), grid.data)
    # the robot on polyswarm/robots, for RViz or Foxglove: where it was, named
    assert robots, "no robot markers reached the subscriber"
    last = {(m.ns, m.id): m for m in robots[-1].markers}
    body, name = last[("robots", 0)], last[("names", 0)]
    assert name.text == "r1" and body.header.frame_id == "map"
    here = np.array([body.pose.position.x, body.pose.position.y])
    assert np.hypot(*(here - agent.pose[:2])) < 0.5  # sent at most 0.5 s before the end
