"""tf between the agent's node and a real ROS 2 graph (rclpy and Fast DDS from PyPI).

The robot's side: a real rclpy node publishes odometry and scans; its static lidar mount
goes out on ``tf_static`` from a DDS participant (tf2_msgs is not on PyPI, so rclpy
cannot publish it). The agent must read the mount from there and publish
``map -> odom`` on ``tf`` where ROS 2's graph lists it as tf2_msgs/msg/TFMessage."""

from __future__ import annotations

import dataclasses
import math
import random
import time

import numpy as np
import pytest
from geometry_msgs.msg import TransformStamped as RosTransformStamped
from nav_msgs.msg import Odometry as RosOdometry
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan as RosLaserScan

from agents.ros2_tf import dds_topic, transform_stamped
from polyswarm.config import AgentIoConfig, Config
from polyswarm.raycast import cast_rays
from polyswarm.se2 import compose
from tests.conftest import ANGLES, agent_on_a_thread, rclpy_node, room

cyclonedds = pytest.importorskip("cyclonedds")

MOUNT = (0.1, 0.0, math.pi)  # the lidar 0.1 m ahead of the base, facing backwards
START = (1.0, 2.0, 0.0)  # the robot in the map (the room); its odometry starts at 0
SPEED_MPS = 0.2
SCANS = 40  # at 10 Hz: 0.8 m along the room


def _stamp(msg, t: float) -> None:
    msg.header.stamp.sec = math.floor(t)
    msg.header.stamp.nanosec = int((t - math.floor(t)) * 1e9)


def _messages(t: float, t0: float):
    """The odometry and the scan at ``t`` s after ``t0`` (wall seconds, as stamps)."""
    x = SPEED_MPS * t
    odom = RosOdometry()
    _stamp(odom, t0 + t)
    odom.header.frame_id, odom.child_frame_id = "odom", "base_link"
    odom.pose.pose.position.x, odom.pose.pose.orientation.w = x, 1.0
    odom.twist.twist.linear.x = SPEED_MPS
    lidar = compose(compose(START, (x, 0.0, 0.0)), MOUNT)
    s, e = room()
    scan = RosLaserScan()
    _stamp(scan, t0 + t)
    scan.header.frame_id = "laser"
    scan.angle_min, scan.angle_increment = float(ANGLES[0]), float(ANGLES[1] - ANGLES[0])
    scan.angle_max = float(ANGLES[-1])
    scan.range_min, scan.range_max = 0.05, 30.0
    scan.ranges = [float(r) for r in cast_rays(lidar[:2], ANGLES + lidar[2], s, e, 30.0)]
    return odom, scan


class RobotTf:
    """The robot's tf as a DDS participant: the static mount, and a reader of tf."""

    def __init__(self, domain: int, ns: str) -> None:
        from cyclonedds.core import Policy, Qos
        from cyclonedds.domain import DomainParticipant
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        from agents.dds_types import TFMessage, TransformStamped

        cdr = Policy.DataRepresentation(use_cdrv0_representation=True)
        latched = Qos(
            Policy.Reliability.Reliable(0),
            Policy.Durability.TransientLocal,
            Policy.History.KeepLast(1),
            cdr,
        )
        self.dp = DomainParticipant(domain)
        static = Topic(self.dp, dds_topic(f"{ns}/tf_static"), TFMessage)
        self.static = DataWriter(self.dp, static, qos=latched)
        self.static.write(TFMessage([transform_stamped("base_link", "laser", MOUNT, 0.0)]))
        reliable = Qos(Policy.Reliability.Reliable(0), Policy.History.KeepLast(100), cdr)
        self.tf = DataReader(self.dp, Topic(self.dp, dds_topic(f"{ns}/tf"), TFMessage), reliable)
        probe = Topic(self.dp, dds_topic(f"{ns}/probe"), TransformStamped)
        self.probe = DataWriter(self.dp, probe, qos=reliable)


def test_the_agent_node_reads_the_mount_from_tf_static_and_publishes_map_to_odom():
    domain, ns = random.randint(1, 200), "tb"
    io = AgentIoConfig(source="ros2-node", output="none", namespace=ns, domain_id=domain)
    cfg = dataclasses.replace(Config(), agent=io)  # no [slam.mount]: tf's must be used
    robot_tf = RobotTf(domain, ns)
    probes: list = []
    received: list = []
    with rclpy_node(domain, "robot", f"/{ns}") as robot:
        scan_pub = robot.create_publisher(RosLaserScan, "scan", qos_profile_sensor_data)
        odom_pub = robot.create_publisher(RosOdometry, "odom", 50)
        robot.create_subscription(RosTransformStamped, "probe", probes.append, 10)
        with agent_on_a_thread("r1", cfg, START) as result:
            deadline = time.monotonic() + 20.0
            while time.monotonic() < deadline and not (
                scan_pub.get_subscription_count() and odom_pub.get_subscription_count()
            ):
                time.sleep(0.2)
            time.sleep(1.0)
            t0 = time.time()
            for k in range(SCANS):
                odom, scan = _messages(k / 10.0, t0)
                odom_pub.publish(odom)
                scan_pub.publish(scan)
                robot_tf.probe.write(transform_stamped("odom", "base_link", (k, 0.5, 0.25), 7.5))
                time.sleep(0.1)
                received += robot_tf.tf.take(N=100)
            time.sleep(2.0)
            received += robot_tf.tf.take(N=100)
            topics = dict(robot.get_topic_names_and_types())
    agent = result["agent"]
    # the mount came from tf_static: the scans lined up with the lidar facing backwards
    m = agent.slam.cfg.mount
    assert (m.x_m, m.y_m) == pytest.approx(MOUNT[:2], abs=1e-6)
    assert abs(math.remainder(m.yaw_rad - MOUNT[2], 2 * math.pi)) < 1e-6
    assert agent.stats.scans >= SCANS - 2
    truth = compose(START, (SPEED_MPS * (SCANS - 1) / 10.0, 0.0, 0.0))
    assert np.hypot(*(agent.pose[:2] - truth[:2])) < 0.05, (agent.pose, truth)
    # ROS 2's graph lists the agent's tf with the type tf2 reads (`ros2 topic list -t`)
    assert "tf2_msgs/msg/TFMessage" in topics.get(f"/{ns}/tf", []), topics
    # map -> odom: where odometry's origin lies in the map, the robot's start
    sent = [tr for msg in received for tr in msg.transforms]
    assert len(sent) >= 10, len(sent)
    last = sent[-1]
    assert (last.header.frame_id, last.child_frame_id) == ("map", "odom")
    t, q = last.transform.translation, last.transform.rotation
    assert np.hypot(t.x - START[0], t.y - START[1]) < 0.05, (t, START)
    assert abs(2 * math.atan2(q.z, q.w) - START[2]) < 0.02
    assert last.header.stamp.sec >= math.floor(t0)  # stamped in ROS time, not 0
    # a geometry_msgs/TransformStamped (what TFMessage holds) written the way tf is
    # written reads back in rclpy (Fast DDS) field for field: the same CDR
    assert probes, "rclpy received nothing from the DDS writer"
    p = probes[-1]
    assert (p.header.frame_id, p.child_frame_id) == ("odom", "base_link")
    assert (p.header.stamp.sec, p.header.stamp.nanosec) == (7, 500_000_000)
    assert p.transform.translation.y == 0.5 and p.transform.translation.x >= 1.0
    assert p.transform.rotation.z == pytest.approx(math.sin(0.125))


def _tf(*transforms):
    from agents.dds_types import TFMessage

    return TFMessage([transform_stamped(*t) for t in transforms])


def test_a_robots_frames_give_the_mount_from_tf_static_else_from_tf():
    from agents.sources import RosFrames
    from protocols.tf import TF, TF_STATIC

    moving = ("odom", "base_link", (3.0, 1.0, 0.5), 10.0)
    ros1 = RosFrames()  # a ROS 1 setup: the mount republished on /tf beside odometry
    ros1.scan_frame, ros1.base_frame = "laser", "base_link"
    ros1.add_tf(_tf(moving, ("base_link", "laser", (0.2, 0.0, 0.0), 10.0)), TF)
    found = ros1.mount()
    assert found.static is None and found.dynamic.x_m == pytest.approx(0.2)
    assert ros1.mount() is None  # said once
    both = RosFrames()  # /tf_static wins where both say it, and they disagree
    both.add_tf(_tf(moving, ("base_link", "laser", (0.2, 0.0, 0.0), 10.0)), TF)
    both.add_tf(_tf(("base_link", "laser", MOUNT, 0.0)), TF_STATIC)
    assert both.mount() is None  # the frames are not known yet
    both.scan_frame, both.base_frame = "laser", "base_link"
    found = both.mount()
    assert found.best()[1] == TF_STATIC and found.best()[0].x_m == pytest.approx(0.1)
    assert "disagree" in found.disagreement()
    loop = RosFrames()  # a tf loop on /tf: said, dropped, and /tf_static still read
    loop.scan_frame, loop.base_frame = "laser", "base_link"
    loop.add_tf(_tf(("a", "b", (0, 0, 0), 1.0), ("b", "a", (0, 0, 0), 1.0)), TF)
    loop.add_tf(_tf(("a", "laser", (0, 0, 0), 1.0)), TF)  # laser -> a -> b -> a ...
    assert loop.mount() is None
    loop.add_tf(_tf(("base_link", "laser", MOUNT, 0.0)), TF_STATIC)
    assert loop.mount().best()[1] == TF_STATIC
