"""The agent as a node of the robot's own ROS 2 graph (``[agent] source = "ros2-node"``).

With rclpy installed (a ROS 2 installation, or ROS 2 Jazzy's packages from PyPI:
``pip install 'polyswarm[ros2]'``) the agent joins the robot's DDS domain as the node
``polyswarm_agent_<id>`` in the robot's namespace, and shows up in ``ros2 node list``:

* in: ``scan`` (sensor_msgs/LaserScan, sensor-data QoS) and ``odom`` (nav_msgs/Odometry),
  turned into the agent's own messages on arrival, so its loop is that of every source;
* out: ``map`` (nav_msgs/OccupancyGrid of the map the robot plans on: the merged map
  once the coordinator shares it; reliable and transient-local as map_server's; at
  most once a second and only when the map changed), ``polyswarm/frontiers`` and
  ``polyswarm/robots`` (visualization_msgs/MarkerArray: the map's frontier vectors and
  the robot's target; the robots, their headings and the path).
* tf (``agents.ros2_tf``, a DDS participant of its own: tf2_msgs is not among the ROS 2
  packages on PyPI): the lidar's mount from ``tf_static``, else ``tf``; out on ``tf``
  the map frame -> the odometry's frame, so RViz and Nav2 see the robot in the map
  polyswarm publishes.
* output ``nav2``: goals through Nav2's ``navigate_to_pose`` action
  (``agents.ros2_action``); success ends the target, an abort tells the coordinator it
  failed, a new assignment cancels the goal before.
"""

from __future__ import annotations

import logging
import math
import threading
import time

import numpy as np

from polyswarm.config import CommandOutput
from polyswarm.errors import ConfigError
from polyswarm.polymap import VectorType
from polyswarm.slam.scan import LaserScan
from protocols.messages import Odometry, Scan

log = logging.getLogger(__name__)

NODE_NAME = "polyswarm_agent"
MAP_PERIOD_S = 1.0  # the map is published at most this often (map_server latches once)
MAP_RESOLUTION_M = 0.05  # the OccupancyGrid's cells: the evidence grid's
FRONTIER_WIDTH_M = 0.05  # line width of the frontier markers
SCAN_DEPTH = 50  # sweeps held for the executor: 10 s of a 5 Hz lidar
ROBOTS_PERIOD_S = 0.5  # the robots' markers at most this often (a pose goes out at 2 Hz)
ROBOT_MARKER_M = 0.35  # diameter of a robot's marker
TF_PERIOD_S = 0.05  # map -> odom at most this often (20 Hz, as slam_toolbox's default)
# map -> odom is stamped this far ahead, so a lookup at the newest odometry finds it
# (slam_toolbox's transform_timeout and AMCL's transform_tolerance do the same)
TF_AHEAD_S = 0.2


def _stamp(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def topic(template: str) -> str:
    """A key template of ``AgentIoConfig`` as a topic name relative to the node's
    namespace (``{ns}/scan`` -> ``scan``)."""
    return template.replace("{ns}", "").strip("/")


class Ros2Node:
    """The agent's node: subscriptions that feed ``bus`` (``Bus.inject``), publishers of
    the map and the frontiers, and an executor on a thread of its own."""

    def __init__(self, bus, io, robot_id: str, frames) -> None:
        try:
            import rclpy
            from rclpy.executors import SingleThreadedExecutor
            from rclpy.qos import (
                DurabilityPolicy,
                QoSProfile,
                ReliabilityPolicy,
                qos_profile_sensor_data,
            )
        except ImportError as e:
            raise ConfigError(
                "agent.source = 'ros2-node' needs rclpy: source a ROS 2 installation, or "
                "pip install 'polyswarm[ros2]' (ROS 2 Jazzy's rclpy and Fast DDS from PyPI)"
            ) from e
        from nav_msgs.msg import OccupancyGrid
        from nav_msgs.msg import Odometry as RosOdometry
        from sensor_msgs.msg import LaserScan as RosLaserScan
        from visualization_msgs.msg import MarkerArray

        self.bus, self.io, self.frames = bus, io, frames
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=io.domain_id)
        self.node = rclpy.create_node(
            f"{NODE_NAME}_{robot_id}", namespace="/" + io.namespace.strip("/"), context=self.context
        )
        self.scan_topic, self.odom_topic = topic(io.scan_key), topic(io.odom_key)
        # best effort like every lidar driver, but a deeper history than the sensor-data
        # profile's 5: a sweep that arrives while the executor is busy is not lost
        sensor = QoSProfile(
            depth=SCAN_DEPTH,
            reliability=qos_profile_sensor_data.reliability,
            durability=qos_profile_sensor_data.durability,
        )
        self.node.create_subscription(RosLaserScan, self.scan_topic, self._on_scan, sensor)
        self.node.create_subscription(RosOdometry, self.odom_topic, self._on_odom, 50)
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        self.map_pub = self.node.create_publisher(OccupancyGrid, "map", latched)
        self.marker_pub = self.node.create_publisher(MarkerArray, "polyswarm/frontiers", 10)
        self.robots_pub = self.node.create_publisher(MarkerArray, "polyswarm/robots", 10)
        self._last_robots_s = -math.inf
        self._cdr_pubs: dict = {}  # (topic template, ROS type) -> publisher
        self._published: tuple | None = None  # (map identity, version) last published
        self._seen: tuple | None = None  # ... and last seen, at wall time _changed_at
        self._changed_at = time.time()
        self._last_map_s = -math.inf
        self.maps_published = 0
        self.tf = self._tf_link(io)
        self.nav = None  # output "nav2": agents.ros2_action.Nav2Goals
        if io.output == CommandOutput.NAV2:
            from agents.ros2_action import Nav2Goals

            self.nav = Nav2Goals(io.domain_id, io.key(io.nav2_action_key), io.map_frame)
        self._last_tf_s = -math.inf
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name="ros2-node", daemon=True)
        self._thread.start()

    def _tf_link(self, io):
        """The tf participant, or None (said once) without Cyclone DDS."""
        from agents.ros2_tf import TfLink

        try:
            return TfLink(io.domain_id, io.key(io.tf_key), io.key(io.tf_static_key), self._on_tf)
        except ConfigError as e:
            log.warning("no tf in or out: %s; the mount comes from [slam.mount]", e)
            return None

    def _on_tf(self, msg, topic: str) -> None:
        self.frames.add_tf(msg, topic)

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:  # the context shut down under it: the agent is stopping
            log.debug("ros2 executor stopped", exc_info=True)

    def _on_scan(self, msg) -> None:
        self.frames.scan_frame = msg.header.frame_id
        s = LaserScan(
            np.asarray(msg.ranges, dtype=np.float64),
            msg.angle_min,
            msg.angle_increment,
            msg.range_min,
            msg.range_max,
            _stamp(msg.header),
            msg.time_increment,
            msg.scan_time,
        )
        self.bus.inject(self.scan_topic, s.stamp, Scan.from_laserscan(s))

    def _on_odom(self, msg) -> None:
        self.frames.base_frame = msg.child_frame_id
        self.frames.odom_frame = msg.header.frame_id
        p, t = msg.pose.pose, msg.twist.twist
        odom = Odometry(p.position.x, p.position.y, _yaw(p.orientation), t.linear.x, t.angular.z)
        self.bus.inject(self.odom_topic, _stamp(msg.header), odom)

    def put_cdr(self, template: str, ros_type: str, cdr: bytes, reliable: bool = False) -> None:
        """Publish a message already serialised (CDR, as ``protocols.ros`` encodes it)
        on the topic of ``template``: the agent's velocity commands and goals."""
        import importlib

        key = (template, ros_type)
        pub = self._cdr_pubs.get(key)
        if pub is None:
            package, _, name = ros_type.split("/")
            kind = getattr(importlib.import_module(f"{package}.msg"), name)
            pub = self.node.create_publisher(kind, topic(template), 10)
            self._cdr_pubs[key] = pub
        pub.publish(cdr)

    def names(self) -> list[str]:
        """The nodes this node sees in its graph (``ros2 node list``)."""
        return [f"{ns.rstrip('/')}/{n}" for n, ns in self.node.get_node_names_and_namespaces()]

    def publish_map_to_odom(self, pose, odom, force: bool = False) -> bool:
        """The map frame -> the odometry's frame on tf, from the robot's pose in the map
        and its odometry pose at the same time (x m, y m, yaw rad), at most every
        ``TF_PERIOD_S``; whether it was sent (not before odometry named its frame)."""
        from polyswarm.se2 import compose, inverse

        now = time.time()
        if self.tf is None or not self.frames.odom_frame or odom is None:
            return False
        if not force and now - self._last_tf_s < TF_PERIOD_S:
            return False
        self._last_tf_s = now
        map_to_odom = compose(np.asarray(pose, float), inverse(np.asarray(odom, float)))
        self.tf.publish(self.io.map_frame, self.frames.odom_frame, map_to_odom, now + TF_AHEAD_S)
        return True

    def publish_map(self, pmap, target=None, force: bool = False) -> bool:
        """Publish ``pmap`` on ``map`` (and its frontiers) if it changed and the last
        publication is ``MAP_PERIOD_S`` old; whether it was published."""
        now = time.monotonic()
        ident = (id(pmap), pmap.version)
        if ident != self._seen:  # the map changed: stamped with when it was seen so
            self._seen, self._changed_at = ident, time.time()
        if not force and (ident == self._published or now - self._last_map_s < MAP_PERIOD_S):
            return False
        if not pmap.cells:
            return False
        self.map_pub.publish(self.occupancy_grid(pmap))
        self.marker_pub.publish(self.frontier_markers(pmap, target))
        self._published, self._last_map_s = ident, now
        self.maps_published += 1
        return True

    def occupancy_grid(self, pmap):
        """``pmap`` as a nav_msgs/OccupancyGrid at ``MAP_RESOLUTION_M`` in ``map_frame``."""
        from geometry_msgs.msg import Pose
        from nav_msgs.msg import MapMetaData, OccupancyGrid

        from polyswarm.grids.convert import polymap_to_grid

        grid = polymap_to_grid(pmap, MAP_RESOLUTION_M)
        msg = OccupancyGrid()
        msg.header.frame_id = self.io.map_frame
        sec = math.floor(self._changed_at)  # the time of the map's change
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, int((self._changed_at - sec) * 1e9)
        rows, cols = grid.shape
        origin = Pose()
        origin.position.x, origin.position.y = float(grid.origin[0]), float(grid.origin[1])
        origin.orientation.w = 1.0
        msg.info = MapMetaData(
            resolution=float(grid.resolution), width=cols, height=rows, origin=origin
        )
        msg.data = grid.data.reshape(-1).tolist()
        return msg

    def frontier_markers(self, pmap, target=None):
        """The map's frontier vectors as one LINE_LIST marker, the target as a sphere."""
        from geometry_msgs.msg import Point
        from visualization_msgs.msg import Marker, MarkerArray

        stamp = self.node.get_clock().now().to_msg()
        lines = Marker(type=Marker.LINE_LIST, action=Marker.ADD, ns="frontiers", id=0)
        lines.header.frame_id, lines.header.stamp = self.io.map_frame, stamp
        lines.scale.x = FRONTIER_WIDTH_M
        lines.color.g, lines.color.a = 0.63, 1.0
        lines.pose.orientation.w = 1.0
        s, e, _ = pmap.vectors([VectorType.FRONTIER])
        for a, b in zip(s, e, strict=True):
            lines.points += [Point(x=float(p[0]), y=float(p[1])) for p in (a, b)]
        out = MarkerArray(markers=[lines])
        if target is not None:
            t = Marker(type=Marker.SPHERE, action=Marker.ADD, ns="target", id=1)
            t.header.frame_id, t.header.stamp = self.io.map_frame, stamp
            t.pose.position.x, t.pose.position.y = float(target[0]), float(target[1])
            t.pose.orientation.w = 1.0
            t.scale.x = t.scale.y = t.scale.z = 0.3
            t.color.b, t.color.a = 0.75, 1.0
            out.markers.append(t)
        return out

    def publish_robots(self, robot_id: str, pose, path, peers: dict, force: bool = False) -> bool:
        """This robot (a cylinder, an arrow for its heading, the rest of its path) and the
        robots it last heard of (cylinders at their last positions, named) on
        ``polyswarm/robots``, at most every ``ROBOTS_PERIOD_S``; whether it was sent."""
        now = time.monotonic()
        if not force and now - self._last_robots_s < ROBOTS_PERIOD_S:
            return False
        self._last_robots_s = now
        self.robots_pub.publish(self.robot_markers(robot_id, pose, path, peers))
        return True

    def robot_markers(self, robot_id: str, pose, path, peers: dict):
        from geometry_msgs.msg import Point
        from visualization_msgs.msg import Marker, MarkerArray

        stamp = self.node.get_clock().now().to_msg()

        def marker(kind: int, ns: str, k: int) -> Marker:
            m = Marker(type=kind, action=Marker.ADD, ns=ns, id=k)
            m.header.frame_id, m.header.stamp = self.io.map_frame, stamp
            m.pose.orientation.w = 1.0
            m.color.a = 1.0
            return m

        out = []
        everyone = [(robot_id, (float(pose[0]), float(pose[1])))]
        everyone += [(rid, (float(xy[0]), float(xy[1]))) for rid, (_, xy) in sorted(peers.items())]
        for k, (rid, (x, y)) in enumerate(everyone):
            body = marker(Marker.CYLINDER, "robots", k)
            body.pose.position.x, body.pose.position.y, body.pose.position.z = x, y, 0.1
            body.scale.x = body.scale.y = ROBOT_MARKER_M
            body.scale.z = 0.2
            body.color.r, body.color.b = (0.9, 0.2) if k == 0 else (0.4, 0.8)
            name = marker(Marker.TEXT_VIEW_FACING, "names", k)
            name.pose.position.x, name.pose.position.y, name.pose.position.z = x, y, 0.5
            name.scale.z, name.text = 0.25, rid
            name.color.r = name.color.g = name.color.b = 1.0
            out += [body, name]
        heading = marker(Marker.ARROW, "heading", 0)
        x, y, th = (float(v) for v in pose)
        heading.points = [
            Point(x=x, y=y),
            Point(x=x + 0.5 * math.cos(th), y=y + 0.5 * math.sin(th)),
        ]
        heading.scale.x, heading.scale.y, heading.scale.z = 0.05, 0.1, 0.1
        heading.color.r = 0.9
        route = marker(Marker.LINE_STRIP, "path", 0)
        route.points = [Point(x=float(px), y=float(py)) for px, py in path]
        route.scale.x = 0.04
        route.color.r, route.color.g = 0.9, 0.6
        out += [heading, route] if len(route.points) > 1 else [heading]
        return MarkerArray(markers=out)

    def close(self) -> None:
        if self.tf is not None:
            self.tf.close()
        if self.nav is not None:
            self.nav.close()
        try:
            self.executor.shutdown(timeout_sec=1.0)
            self.node.destroy_node()
        finally:
            if self.context.ok():
                self.context.shutdown()
        self._thread.join(timeout=2.0)
