"""Sensor sources and command sinks of a robot agent.

* native: polyswarm ``Scan``/``Odometry`` in, ``CmdVel`` out (the simulator, log replay);
* ros2: sensor_msgs/LaserScan, nav_msgs/Odometry and /tf_static CDR in, as
  zenoh-bridge-ros2dds exposes them (keys from ``AgentIoConfig``); geometry_msgs/Twist
  CDR out on cmd_vel, or a geometry_msgs/PoseStamped goal for the robot's own
  navigation stack;
* rmw_zenoh: the same messages on the keys of a robot whose ROS 2 runs on rmw_zenoh
  (no bridge): the agent is a ROS 2 node there, with liveliness tokens for itself, its
  subscriptions and its publishers, and the attachment rmw_zenoh puts on every message
  (``protocols.rmw_zenoh``).

ROS messages are turned into the native messages on arrival, so the agent's loop is
the same for every source. The lidar's mount is read from /tf_static (``RosFrames``).
"""

from __future__ import annotations

import logging
import math
import os
import threading
import time
from collections import deque

from polyswarm.config import AgentIoConfig, CommandOutput, SensorSource
from polyswarm.errors import DataFormatError
from protocols import rmw_zenoh as rz
from protocols import ros
from protocols.keys import RobotKeys
from protocols.messages import Assignment, CmdVel, Odometry, Scan
from protocols.tf import TF, TF_STATIC, Mount2D, MountSources, mount_from_tf

log = logging.getLogger(__name__)

NODE_NAME = "polyswarm_agent"
MAX_TF_MESSAGES = 500  # per topic: /tf at 50 Hz for 10 s before the frames are known


class RosFrames:
    """The frames a robot's messages name and its tf: the lidar's mount once the scan's
    frame, the odometry's child frame and a tf path between them are known (from
    /tf_static, else from /tf: ``protocols.tf.MountSources``). Fed from the sources'
    threads."""

    def __init__(self) -> None:
        self.scan_frame = ""
        self.base_frame = ""
        self.odom_frame = ""  # the odometry's own frame (its header's)
        self._tf = {t: deque(maxlen=MAX_TF_MESSAGES) for t in (TF_STATIC, TF)}
        self._lock = threading.Lock()
        self._done = False

    def add_tf(self, msg, topic: str = TF_STATIC) -> None:
        """A TFMessage read on ``topic`` (/tf_static or /tf); /tf's only until the mount
        is known (it carries the moving odom -> base transform many times a second)."""
        with self._lock:
            if topic == TF_STATIC or not self._done:
                self._tf[topic].append(msg)

    def mount(self) -> MountSources | None:
        """The mount as each topic gives it, once (None before it is known, and after it
        was returned)."""
        with self._lock:
            if self._done or not (self.scan_frame and self.base_frame):
                return None
            found = MountSources(*(self._mount_on(t) for t in (TF_STATIC, TF)))
            self._done = found.best()[0] is not None
            return found if self._done else None

    def _mount_on(self, topic: str) -> Mount2D | None:
        """The mount as ``topic``'s messages give it; a bad tree (a loop, a rotation that
        is no quaternion) is said and its messages dropped."""
        try:
            return mount_from_tf(self._tf[topic], self.base_frame, self.scan_frame)
        except DataFormatError as e:
            log.warning("%s: %s; its messages so far are dropped", topic, e)
            self._tf[topic].clear()
            return None


def subscribe_sensors(bus, me: RobotKeys, io: AgentIoConfig, frames: RosFrames) -> list[str]:
    """Subscribe the agent's scan and odometry (and /tf_static); the keys listened to."""
    if io.source == SensorSource.NATIVE:
        bus.subscribe(me.scan, Scan)
        bus.subscribe(me.odom, Odometry)
        return [me.scan, me.odom]

    def on_scan(data: bytes) -> tuple[float, Scan]:
        s, frame = ros.decode_laserscan_framed(data)
        frames.scan_frame = frame
        return s.stamp, Scan.from_laserscan(s)

    def on_odom(data: bytes) -> tuple[float, Odometry]:
        stamp, pose, (v, w), child = ros.decode_odometry_framed(data)
        frames.base_frame = child
        return stamp, Odometry(float(pose[0]), float(pose[1]), float(pose[2]), v, w)

    def on_tf(data: bytes) -> None:
        frames.add_tf(ros.decode_tf(data))

    keys = [topic_key(io, io.scan_key, ros.LASER_SCAN), topic_key(io, io.odom_key, ros.ODOMETRY)]
    tf_key = topic_key(io, io.tf_static_key, ros.TF_MESSAGE)
    bus.subscribe_raw(keys[0], on_scan)
    bus.subscribe_raw(keys[1], on_odom)
    bus.subscribe_raw(tf_key, on_tf)
    return [*keys, tf_key]


def topic_key(io: AgentIoConfig, template: str, ros_type: str, hash_: str = "*") -> str:
    """The Zenoh key of a ROS topic: as the bridge names it, or as rmw_zenoh does (any
    type hash when subscribing: robots built without type hashes publish with none)."""
    name = io.key(template)
    if io.source == SensorSource.RMW_ZENOH:
        return rz.topic_key(io.domain_id, name, ros_type, hash_)
    return name


class RmwZenohNode:
    """The agent as a ROS 2 node on rmw_zenoh: liveliness tokens that make it and its
    topics visible to ``ros2 node list`` / ``ros2 topic info``, and the attachment
    (sequence number, time, GID) on what it publishes."""

    def __init__(self, bus, io: AgentIoConfig, robot_id: str) -> None:
        self.bus, self.io = bus, io
        self.session_id = str(bus.session.info.zid())
        self.node = f"{NODE_NAME}_{robot_id}"
        self._gids: dict[str, bytes] = {}
        self._seq: dict[str, int] = {}
        self.tokens = [rz.node_token(io.domain_id, self.session_id, 0, io.namespace, self.node)]
        subs = [
            (io.scan_key, ros.LASER_SCAN),
            (io.odom_key, ros.ODOMETRY),
            (io.tf_static_key, ros.TF_MESSAGE),
        ]
        for eid, (template, typ) in enumerate(subs, start=1):
            self._token(eid, "MS", template, typ)

    def _token(self, eid: int, kind: str, template: str, ros_type: str) -> None:
        io = self.io
        fq = "/" + io.key(template)
        self.tokens.append(
            rz.entity_token(
                io.domain_id, self.session_id, 0, eid, kind, io.namespace, self.node, fq, ros_type
            )
        )

    def declare(self) -> None:
        for t in self.tokens:
            self.bus.declare_alive(t)

    def publisher(self, template: str, ros_type: str) -> str:
        """Declare a publisher (its token and GID); returns its key."""
        key = topic_key(self.io, template, ros_type, rz.type_hash(ros_type))
        if key not in self._gids:
            self._gids[key] = os.urandom(rz.GID_BYTES)
            self._seq[key] = 0
            self._token(10 + len(self._gids), "MP", template, ros_type)
            self.bus.declare_alive(self.tokens[-1])
        return key

    def put(self, key: str, cdr: bytes, reliable: bool = False) -> None:
        self._seq[key] += 1
        att = rz.encode_attachment(self._seq[key], time.time_ns(), self._gids[key])
        self.bus.put_raw(key, cdr, reliable=reliable, attachment=att)


class CommandSink:
    """Sends the agent's velocity commands (or goals) in the configured form."""

    def __init__(
        self, bus, me: RobotKeys, io: AgentIoConfig, node: RmwZenohNode | None = None, ros2=None
    ):
        self.bus, self.me, self.io, self.node = bus, me, io, node
        self.ros2 = ros2  # agents.ros2_node.Ros2Node: commands go into the robot's graph
        self._goal_target: int | None = None

    def _put(self, template: str, ros_type: str, cdr: bytes, reliable: bool = False) -> None:
        if self.ros2 is not None:
            self.ros2.put_cdr(template, ros_type, cdr, reliable)
        elif self.node is not None:
            self.node.put(self.node.publisher(template, ros_type), cdr, reliable)
        else:
            self.bus.put_raw(self.io.key(template), cdr, reliable=reliable)

    def velocity(self, v_mps: float, w_radps: float, scan_seq: int, stamp_s: float) -> None:
        out = self.io.output
        if out == CommandOutput.NATIVE:
            self.bus.publish(self.me.cmd_vel, CmdVel(v_mps, w_radps, scan_seq), stamp_s)
        elif out == CommandOutput.TWIST:
            self._put(self.io.cmd_vel_key, ros.TWIST, ros.encode_twist(v_mps, w_radps))

    def assignment(self, a: Assignment | None, stamp_s: float, pose=None) -> None:
        """In ``goal`` and ``nav2`` modes, each new assignment goes to the robot's
        navigation stack (``pose``: the robot's, to face the goal from it)."""
        goals = (CommandOutput.GOAL, CommandOutput.NAV2)
        if self.io.output not in goals or a is None or a.target == self._goal_target:
            return
        self._goal_target = a.target
        if self.io.output == CommandOutput.NAV2:
            self._nav2(a, stamp_s, pose)
            return
        data = ros.encode_goal(a.goal, stamp_s, self.io.map_frame)
        self._put(self.io.goal_key, ros.POSE_STAMPED, data, reliable=True)
        log.info("goal (%.2f, %.2f) sent to the navigation stack", *a.goal)

    def _nav2(self, a: Assignment, stamp_s: float, pose) -> None:
        from protocols.messages import AssignmentKind

        nav = self.ros2.nav
        if a.kind == AssignmentKind.STOP:
            nav.stop()
            return
        x, y = (0.0, 0.0) if pose is None else (float(pose[0]), float(pose[1]))
        yaw = math.atan2(a.goal[1] - y, a.goal[0] - x)  # facing the way it came to look
        nav.navigate(a.target, a.goal, yaw, stamp_s)
