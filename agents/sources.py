"""Sensor sources and command sinks of a robot agent.

* native: polyswarm ``Scan``/``Odometry`` in, ``CmdVel`` out (the simulator, log replay);
* ros2: sensor_msgs/LaserScan and nav_msgs/Odometry CDR in, as zenoh-bridge-ros2dds
  exposes them (keys from ``AgentIoConfig``); geometry_msgs/Twist CDR out on cmd_vel, or
  a geometry_msgs/PoseStamped goal for the robot's own navigation stack.

ROS messages are turned into the native messages on arrival, so the agent's loop is
the same for every source.
"""

from __future__ import annotations

import logging

from polyswarm.config import AgentIoConfig, CommandOutput, SensorSource
from protocols import ros
from protocols.keys import RobotKeys
from protocols.messages import Assignment, CmdVel, Odometry, Scan

log = logging.getLogger(__name__)


def _ros_scan(data: bytes) -> tuple[float, Scan]:
    s = ros.decode_laserscan(data)
    return s.stamp, Scan(s.angle_min, s.angle_increment, s.range_min, s.range_max, s.ranges)


def _ros_odom(data: bytes) -> tuple[float, Odometry]:
    stamp, pose, (v, w) = ros.decode_odometry(data)
    return stamp, Odometry(float(pose[0]), float(pose[1]), float(pose[2]), v, w)


def subscribe_sensors(bus, me: RobotKeys, io: AgentIoConfig) -> list[str]:
    """Subscribe the agent's scan and odometry; the keys listened to."""
    if io.source == SensorSource.ROS2:
        scan_key, odom_key = io.key(io.scan_key), io.key(io.odom_key)
        bus.subscribe_raw(scan_key, _ros_scan)
        bus.subscribe_raw(odom_key, _ros_odom)
        return [scan_key, odom_key]
    bus.subscribe(me.scan, Scan)
    bus.subscribe(me.odom, Odometry)
    return [me.scan, me.odom]


class CommandSink:
    """Sends the agent's velocity commands (or goals) in the configured form."""

    def __init__(self, bus, me: RobotKeys, io: AgentIoConfig) -> None:
        self.bus, self.me, self.io = bus, me, io
        self._goal_target: int | None = None

    def velocity(self, v_mps: float, w_radps: float, scan_seq: int, stamp_s: float) -> None:
        out = self.io.output
        if out == CommandOutput.NATIVE:
            self.bus.publish(self.me.cmd_vel, CmdVel(v_mps, w_radps, scan_seq), stamp_s)
        elif out == CommandOutput.TWIST:
            self.bus.put_raw(self.io.key(self.io.cmd_vel_key), ros.encode_twist(v_mps, w_radps))

    def assignment(self, a: Assignment | None, stamp_s: float) -> None:
        """In ``goal`` mode, each new assignment goes to the robot's navigation stack."""
        if self.io.output != CommandOutput.GOAL or a is None or a.target == self._goal_target:
            return
        self._goal_target = a.target
        data = ros.encode_goal(a.goal, stamp_s, self.io.map_frame)
        self.bus.put_raw(self.io.key(self.io.goal_key), data, reliable=True)
        log.info("goal (%.2f, %.2f) sent to the navigation stack", *a.goal)
