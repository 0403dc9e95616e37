"""ROS 2 messages as CDR bytes (what zenoh-bridge-ros2dds carries), without ROS.

Decoders of outside data (LaserScan, Odometry) turn any defect into ``ProtocolError``;
encoders (Twist, OccupancyGrid, OccupancyGridUpdate) are used for velocity output and for
the bandwidth baseline. The ``rosbags`` type store of ROS 2 Humble is used, with
map_msgs/msg/OccupancyGridUpdate registered from its message definition.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from polyswarm.se2 import wrap
from polyswarm.slam.scan import LaserScan
from protocols.messages import MAX_BEAMS, ProtocolError

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TWIST = "geometry_msgs/msg/Twist"
OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"
GRID_UPDATE = "map_msgs/msg/OccupancyGridUpdate"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
MAX_ODOM_VALUE = 1e6  # metres, m/s, rad/s: anything larger is not a robot's odometry
MAX_CDR_BYTES = 16 * 1024 * 1024  # an incoming ROS message larger than this is refused
MAX_SWEEP_S = 1.0  # a scan's beams spread over longer than this: its timing is not trusted

_GRID_UPDATE_MSG = """
std_msgs/Header header
int32 x
int32 y
uint32 width
uint32 height
int8[] data
"""


@functools.cache
def typestore():
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(_GRID_UPDATE_MSG, GRID_UPDATE))
    return store


def _header(stamp_s: float, frame: str):
    ts = typestore()
    Time = ts.types["builtin_interfaces/msg/Time"]
    Header = ts.types["std_msgs/msg/Header"]
    sec = math.floor(stamp_s)
    return Header(stamp=Time(sec=int(sec), nanosec=int((stamp_s - sec) * 1e9)), frame_id=frame)


def _stamp(header) -> float:
    return float(header.stamp.sec) + 1e-9 * float(header.stamp.nanosec)


# --- decoding (outside data) ---------------------------------------------------------------


def _deserialize(data: bytes, typename: str):
    if not isinstance(data, bytes | bytearray | memoryview) or len(data) > MAX_CDR_BYTES:
        raise ProtocolError(f"{typename}: not bytes or larger than {MAX_CDR_BYTES} bytes")
    try:
        return typestore().deserialize_cdr(bytes(data), typename)
    except Exception as e:  # rosbags raises several types on malformed CDR
        raise ProtocolError(f"{typename}: malformed CDR: {e}") from None


def decode_laserscan(data: bytes) -> LaserScan:
    """A sensor_msgs/LaserScan (CDR) as a LaserScan; ProtocolError on any defect."""
    return laserscan_from_msg(_deserialize(data, LASER_SCAN))


def decode_laserscan_framed(data: bytes) -> tuple[LaserScan, str]:
    """A LaserScan (CDR) and its header's frame id."""
    m = _deserialize(data, LASER_SCAN)
    return laserscan_from_msg(m), str(m.header.frame_id)


def decode_odometry_framed(data: bytes):
    """``decode_odometry`` and the odometry's child frame id (the robot's base frame)."""
    m = _deserialize(data, ODOMETRY)
    return (*odometry_from_msg(m), str(m.child_frame_id))


def decode_tf(data: bytes):
    """A tf2_msgs/TFMessage (CDR), as the deserialized message."""
    m = _deserialize(data, TF_MESSAGE)
    for tr in m.transforms:  # every field a transform needs, or a ProtocolError now
        vals = (*(getattr(tr.transform.translation, a) for a in "xyz"),)
        vals += tuple(getattr(tr.transform.rotation, a) for a in "xyzw")
        if not all(math.isfinite(float(v)) for v in vals):
            raise ProtocolError("TFMessage with a non-finite transform")
    return m


def laserscan_from_msg(m) -> LaserScan:
    """A LaserScan message (CDR-decoded, or from a bag of either ROS) as a LaserScan.

    Beams may run clockwise (``angle_increment < 0``); invalid returns may read inf, NaN,
    0 or beyond ``range_max``, as drivers emit them (``polyswarm.slam.scan.classify`` sorts
    them out). ``time_increment`` is kept for de-skewing when it describes a sweep of at
    most ``MAX_SWEEP_S``; otherwise the beams count as taken at once."""
    try:
        with np.errstate(invalid="ignore"):  # NaN beams are legal (invalid returns)
            ranges = np.asarray(m.ranges, dtype=float).reshape(-1)
        vals = tuple(float(v) for v in (m.angle_min, m.angle_increment, m.range_min, m.range_max))
        dt, period = float(m.time_increment), float(m.scan_time)
        stamp = _stamp(m.header)
    except (AttributeError, TypeError, ValueError) as e:
        raise ProtocolError(f"LaserScan: {e}") from None
    if not 2 <= len(ranges) <= MAX_BEAMS:
        raise ProtocolError(f"LaserScan with {len(ranges)} beams")
    if not all(math.isfinite(v) for v in vals) or vals[1] == 0:
        raise ProtocolError("LaserScan with non-finite or zero angles or limits")
    if not 0 <= vals[2] < vals[3]:
        raise ProtocolError(f"LaserScan range limits {vals[2]}..{vals[3]}")
    if abs(vals[1]) * (len(ranges) - 1) > 2 * math.pi + 1e-3:
        raise ProtocolError("LaserScan covers more than a full turn")
    if (ranges[np.isfinite(ranges)] < 0).any():
        raise ProtocolError("LaserScan with negative ranges")
    if not (math.isfinite(dt) and 0 <= dt * (len(ranges) - 1) <= MAX_SWEEP_S):
        dt = 0.0
    return LaserScan(
        ranges,
        vals[0],
        vals[1],
        vals[2],
        vals[3],
        stamp,
        dt,
        period if math.isfinite(period) and period > 0 else 0.0,
    )


def decode_odometry(data: bytes) -> tuple[float, np.ndarray, tuple[float, float]]:
    """A nav_msgs/Odometry (CDR): stamp (s), pose (x, y, yaw) and (v, w)."""
    return odometry_from_msg(_deserialize(data, ODOMETRY))


def odometry_from_msg(m) -> tuple[float, np.ndarray, tuple[float, float]]:
    """An Odometry message: stamp (s), pose (x, y, yaw) and (v, w); ProtocolError on any
    defect."""
    try:
        p, q = m.pose.pose.position, m.pose.pose.orientation
        vals = tuple(
            float(v)
            for v in (p.x, p.y, q.x, q.y, q.z, q.w, m.twist.twist.linear.x, m.twist.twist.angular.z)
        )
        stamp = _stamp(m.header)
    except (AttributeError, TypeError, ValueError) as e:
        raise ProtocolError(f"Odometry: {e}") from None
    if not all(math.isfinite(v) and abs(v) <= MAX_ODOM_VALUE for v in vals):
        raise ProtocolError(f"Odometry with non-finite or values beyond {MAX_ODOM_VALUE:g}")
    x, y, qx, qy, qz, qw, v, w = vals
    norm = math.hypot(qx, qy, qz, qw)
    if not 0.5 < norm < 1.5:
        raise ProtocolError(f"Odometry orientation is not a unit quaternion (norm {norm:.3f})")
    yaw = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy**2 + qz**2))
    return stamp, np.array([x, y, wrap(yaw)]), (v, w)


# --- encoding --------------------------------------------------------------------------------


def encode_twist(v_mps: float, w_radps: float) -> bytes:
    ts = typestore()
    Vector3 = ts.types["geometry_msgs/msg/Vector3"]
    Twist = ts.types[TWIST]
    msg = Twist(linear=Vector3(x=v_mps, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=w_radps))
    return bytes(ts.serialize_cdr(msg, TWIST))


def decode_twist(data: bytes) -> tuple[float, float]:
    m = _deserialize(data, TWIST)
    return float(m.linear.x), float(m.angular.z)


def encode_laserscan(scan: LaserScan, frame: str = "laser") -> bytes:
    ts = typestore()
    LaserScanMsg = ts.types[LASER_SCAN]
    msg = LaserScanMsg(
        header=_header(scan.stamp, frame),
        angle_min=scan.angle_min,
        angle_max=scan.angle_min + scan.angle_increment * (len(scan.ranges) - 1),
        angle_increment=scan.angle_increment,
        time_increment=scan.time_increment,
        scan_time=scan.scan_time or 0.1,
        range_min=scan.range_min,
        range_max=scan.range_max,
        ranges=np.asarray(scan.ranges, dtype=np.float32),
        intensities=np.zeros(0, dtype=np.float32),
    )
    return bytes(ts.serialize_cdr(msg, LASER_SCAN))


def encode_odometry(stamp_s: float, pose, v_mps: float = 0.0, w_radps: float = 0.0) -> bytes:
    ts = typestore()
    t = ts.types
    x, y, th = (float(v) for v in pose)
    cov = np.zeros(36, dtype=np.float64)
    msg = t[ODOMETRY](
        header=_header(stamp_s, "odom"),
        child_frame_id="base_link",
        pose=t["geometry_msgs/msg/PoseWithCovariance"](
            pose=t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                orientation=t["geometry_msgs/msg/Quaternion"](
                    x=0.0, y=0.0, z=math.sin(th / 2), w=math.cos(th / 2)
                ),
            ),
            covariance=cov,
        ),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t[TWIST](
                linear=t["geometry_msgs/msg/Vector3"](x=v_mps, y=0.0, z=0.0),
                angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=w_radps),
            ),
            covariance=cov.copy(),
        ),
    )
    return bytes(ts.serialize_cdr(msg, ODOMETRY))


def encode_occupancy_grid(
    data: np.ndarray, resolution_m: float, origin_xy, stamp_s: float = 0.0, frame: str = "map"
) -> bytes:
    """nav_msgs/OccupancyGrid of int8 ``data`` (row 0 = lowest y), as CDR."""
    ts = typestore()
    t = ts.types
    rows, cols = data.shape
    msg = t[OCCUPANCY_GRID](
        header=_header(stamp_s, frame),
        info=t["nav_msgs/msg/MapMetaData"](
            map_load_time=_header(stamp_s, frame).stamp,
            resolution=resolution_m,
            width=cols,
            height=rows,
            origin=t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](
                    x=float(origin_xy[0]), y=float(origin_xy[1]), z=0.0
                ),
                orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            ),
        ),
        data=np.ascontiguousarray(data, dtype=np.int8).reshape(-1),
    )
    return bytes(ts.serialize_cdr(msg, OCCUPANCY_GRID))


def encode_grid_update(
    data: np.ndarray, row0: int, col0: int, stamp_s: float = 0.0, frame: str = "map"
) -> bytes:
    """map_msgs/OccupancyGridUpdate of the rectangle ``data`` at (col0, row0), as CDR."""
    ts = typestore()
    rows, cols = data.shape
    msg = ts.types[GRID_UPDATE](
        header=_header(stamp_s, frame),
        x=int(col0),
        y=int(row0),
        width=cols,
        height=rows,
        data=np.ascontiguousarray(data, dtype=np.int8).reshape(-1),
    )
    return bytes(ts.serialize_cdr(msg, GRID_UPDATE))


def encode_goal(goal_xy, stamp_s: float = 0.0, frame: str = "map", yaw_rad: float = 0.0) -> bytes:
    """geometry_msgs/PoseStamped of a goal point (for the robot's own navigation stack)."""
    ts = typestore()
    t = ts.types
    msg = t["geometry_msgs/msg/PoseStamped"](
        header=_header(stamp_s, frame),
        pose=t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=float(goal_xy[0]), y=float(goal_xy[1]), z=0.0),
            orientation=t["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=math.sin(yaw_rad / 2), w=math.cos(yaw_rad / 2)
            ),
        ),
    )
    return bytes(ts.serialize_cdr(msg, "geometry_msgs/msg/PoseStamped"))


def decode_goal(data: bytes) -> tuple[float, float]:
    m = _deserialize(data, "geometry_msgs/msg/PoseStamped")
    return float(m.pose.position.x), float(m.pose.position.y)
