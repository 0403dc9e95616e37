"""Recorded bags for tests and benchmarks: a robot circling a pillar in a room, its lidar
upside down.

The room is 8 x 6 m with a 1 x 1 m pillar in the middle; the robot drives a circle of
2 m radius around the pillar. The lidar sits 0.1 m ahead of base_link and is mounted
upside down (a roll of pi), so its beams run clockwise seen from above; /tf_static
says so through base_footprint -> base_link -> laser. Ranges are exact (ray casting),
odometry carries a small heading drift, so SLAM has something to correct.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

ROOM = [((0, 0), (8, 0)), ((8, 0), (8, 6)), ((8, 6), (0, 6)), ((0, 6), (0, 0))]
PILLAR = [((3.5, 2.5), (4.5, 2.5)), ((4.5, 2.5), (4.5, 3.5)), ((4.5, 3.5), (3.5, 3.5))]
PILLAR += [((3.5, 3.5), (3.5, 2.5))]
MOUNT = (0.1, 0.0, 0.0, True)  # x, y (m), yaw (rad), upside down
BEAMS = 360
RANGE_MAX_M = 6.0


def ray_cast(origin, angles: np.ndarray) -> np.ndarray:
    """Distance along each ray (world angles) to the nearest wall; inf when none."""
    segs = np.array(ROOM + PILLAR, dtype=float)
    a, b = segs[:, 0], segs[:, 1]
    d = np.stack([np.cos(angles), np.sin(angles)], axis=1)[:, None, :]
    e = (b - a)[None, :, :]
    w = (a - np.asarray(origin))[None, :, :]
    den = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * e[..., 1] - w[..., 1] * e[..., 0]) / den
        u = (w[..., 0] * d[..., 1] - w[..., 1] * d[..., 0]) / den
    ok = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
    return np.where(ok, t, np.inf).min(axis=1)


def trajectory(n_scans: int, rate_hz: float = 10.0):
    """(stamps, true poses) of the circle, one per scan."""
    t = np.arange(n_scans) / rate_hz
    phi = 2 * math.pi * t / 40.0  # one lap in 40 s: 0.31 m/s
    x, y = 4 + 2 * np.cos(phi), 3 + 2 * np.sin(phi)
    return t + 100.0, np.stack([x, y, phi + math.pi / 2], axis=1)


_MX, _MY, _MYAW, _ = MOUNT
_INC = -2 * math.pi / BEAMS  # upside down: the sensor's angles run clockwise
_ANGLE_MIN = math.pi - 1e-6


class _Messages:
    """The messages of a made bag: headers, transforms, scans and odometry of the route."""

    def __init__(
        self,
        T,
        ros1: bool,
        n_scans: int,
        blind: bool,
        odom_shift_s: float,
        mount_yaw_error_rad: float,
    ) -> None:
        self.T, self.ros1, self.blind = T, ros1, blind
        self.odom_shift_s, self.mount_yaw_error_rad = odom_shift_s, mount_yaw_error_rad
        self.stamps, self.poses = trajectory(n_scans)
        self.odo = self.poses.copy()
        self.odo[:, 2] += 0.002 * np.arange(n_scans)  # heading drift: 0.02 rad/s

    def header(self, t: float, frame: str):
        sec = math.floor(t)
        stamp = self.T["builtin_interfaces/msg/Time"](sec=sec, nanosec=int((t - sec) * 1e9))
        if self.ros1:
            return self.T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        return self.T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def transform(self, parent, child, xyz, quat):
        return self.T["geometry_msgs/msg/TransformStamped"](
            header=self.header(self.stamps[0], parent),
            child_frame_id=child,
            transform=self.T["geometry_msgs/msg/Transform"](
                translation=self.T["geometry_msgs/msg/Vector3"](x=xyz[0], y=xyz[1], z=xyz[2]),
                rotation=self.T["geometry_msgs/msg/Quaternion"](
                    x=quat[0], y=quat[1], z=quat[2], w=quat[3]
                ),
            ),
        )

    def scan_msg(self, k: int):
        x, y, th = self.poses[k]
        sx, sy = (
            x + _MX * math.cos(th) - _MY * math.sin(th),
            y + _MX * math.sin(th) + _MY * math.cos(th),
        )
        sensor = _ANGLE_MIN + _INC * np.arange(BEAMS)
        world = th + _MYAW - sensor  # upside down: a sensor angle points the other way
        r = ray_cast((sx, sy), world)
        r = np.where((r <= RANGE_MAX_M) & (not self.blind), r, np.inf).astype(np.float32)
        return self.T["sensor_msgs/msg/LaserScan"](
            header=self.header(self.stamps[k], "laser"),
            angle_min=_ANGLE_MIN,
            angle_max=_ANGLE_MIN + _INC * (BEAMS - 1),
            angle_increment=_INC,
            time_increment=0.0,
            scan_time=0.1,
            range_min=0.12,
            range_max=RANGE_MAX_M,
            ranges=r,
            intensities=np.zeros(0, dtype=np.float32),
        )

    def odom_msg(self, k: int):
        x, y, th = self.odo[k]
        cov = np.zeros(36)
        return self.T["nav_msgs/msg/Odometry"](
            header=self.header(self.stamps[k] + self.odom_shift_s, "odom"),
            child_frame_id="base_footprint",
            pose=self.T["geometry_msgs/msg/PoseWithCovariance"](
                pose=self.T["geometry_msgs/msg/Pose"](
                    position=self.T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                    orientation=self.T["geometry_msgs/msg/Quaternion"](
                        x=0.0, y=0.0, z=math.sin(th / 2), w=math.cos(th / 2)
                    ),
                ),
                covariance=cov,
            ),
            twist=self.T["geometry_msgs/msg/TwistWithCovariance"](
                twist=self.T["geometry_msgs/msg/Twist"](
                    linear=self.T["geometry_msgs/msg/Vector3"](x=0.31, y=0.0, z=0.0),
                    angular=self.T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.157),
                ),
                covariance=cov.copy(),
            ),
        )

    def mount_tf(self, dx: float = 0.0):
        e = self.mount_yaw_error_rad / 2  # roll pi, then the yaw error about the base's z axis
        quat = (math.cos(e), math.sin(e), 0.0, 0.0)
        return self.transform("base_link", "laser", (_MX + dx, _MY, 0.2), quat)


def make_bag(
    path: Path,
    kind: str = "mcap",
    n_scans: int = 200,
    topics=("/scan", "/odom", "/tf_static"),
    defects: bool = False,
    mount_topic: str = "/tf_static",
    mount_yaw_error_rad: float = 0.0,
    tf_mount_error_m: float | None = None,
    scan_copies=(),
    odom_shift_s: float = 0.0,
    blind: bool = False,
) -> Path:
    """Write the bag: ``kind`` 'mcap' or 'sqlite3' (rosbag2) or 'ros1'. ``defects``: scan
    10 has no beams, odometry 20 comes twice, scans 30 and 31 are recorded in the wrong
    order of their stamps.

    The mount goes on ``mount_topic`` ('/tf' as ROS 1 setups do: then the moving
    odom -> base_footprint transform is there too), its yaw ``mount_yaw_error_rad`` off
    the lidar's true one; ``tf_mount_error_m``: /tf also carries the mount, that many
    metres off in x (two mounts that disagree). ``scan_copies``: more LaserScan topics
    with the same scans (a /stable_scan beside /scan). ``odom_shift_s``: odometry stamps
    shifted by that (0: they overlap the scans). ``blind``: no beam has a return."""
    from rosbags.typesys import Stores, get_typestore

    ros1 = kind == "ros1"
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in store.types:
        from rosbags.typesys import get_types_from_msg

        defn = "geometry_msgs/TransformStamped[] transforms"
        store.register(get_types_from_msg(defn, "tf2_msgs/msg/TFMessage"))
    T = store.types
    m = _Messages(T, ros1, n_scans, blind, odom_shift_s, mount_yaw_error_rad)
    stamps, odo = m.stamps, m.odo

    base = m.transform("base_footprint", "base_link", (0.0, 0.0, 0.05), (0.0, 0.0, 0.0, 1.0))
    tfm = "tf2_msgs/msg/TFMessage"
    first = int(stamps[0] * 1e9) - 1
    messages = [(first, mount_topic, tfm, T[tfm](transforms=[base, m.mount_tf()]))]
    if tf_mount_error_m is not None:
        messages.append(
            (first, "/tf", tfm, T[tfm](transforms=[base, m.mount_tf(tf_mount_error_m)]))
        )
    for k in range(n_scans):
        ns = int(stamps[k] * 1e9)
        messages.append((ns, "/odom", "nav_msgs/msg/Odometry", m.odom_msg(k)))
        if defects and k == 20:
            messages.append((ns, "/odom", "nav_msgs/msg/Odometry", m.odom_msg(k)))
        if mount_topic == "/tf":  # the moving part of the tree, beside the mount
            x, y, th = odo[k]
            q = (0.0, 0.0, math.sin(th / 2), math.cos(th / 2))
            moving = m.transform("odom", "base_footprint", (x, y, 0.0), q)
            messages.append((ns, "/tf", tfm, T[tfm](transforms=[moving, base, m.mount_tf()])))
        scan = m.scan_msg(31 if defects and k == 30 else 30 if defects and k == 31 else k)
        if defects and k == 10:
            scan.ranges = np.zeros(0, dtype=np.float32)
        for topic in ("/scan", *scan_copies):
            messages.append((ns + 1, topic, "sensor_msgs/msg/LaserScan", scan))
    wanted = set(topics) | set(scan_copies) | {mount_topic}
    if tf_mount_error_m is not None:
        wanted.add("/tf")
    _write(path, kind, store, [m for m in messages if m[1] in wanted])
    return path


def without_definitions(path: Path) -> Path:
    """A rosbag2 sqlite3 bag (``make_bag(..., "sqlite3")``) made as ROS 2 Humble writes
    one: no message definitions, no type hashes, metadata version 5."""
    import sqlite3

    import yaml

    db = next(path.glob("*.db3"))
    con = sqlite3.connect(db)
    con.executescript(
        """
        DROP TABLE message_definitions;
        CREATE TABLE humble_topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL,
            type TEXT NOT NULL, serialization_format TEXT NOT NULL,
            offered_qos_profiles TEXT NOT NULL);
        INSERT INTO humble_topics
            SELECT id, name, type, serialization_format, offered_qos_profiles FROM topics;
        DROP TABLE topics;
        ALTER TABLE humble_topics RENAME TO topics;
        UPDATE schema SET schema_version = 3;
        """
    )
    con.commit()
    con.close()
    meta = yaml.safe_load((path / "metadata.yaml").read_text())
    info = meta["rosbag2_bagfile_information"]
    info["version"], info["ros_distro"] = 5, "humble"
    for t in info["topics_with_message_count"]:
        t["topic_metadata"].pop("type_description_hash", None)
    (path / "metadata.yaml").write_text(yaml.safe_dump(meta))
    return path


def _write(path: Path, kind: str, store, messages) -> None:
    if kind == "ros1":
        from rosbags.rosbag1 import Writer

        with Writer(path) as w:
            conns = {}
            for ns, topic, typ, msg in messages:
                if topic not in conns:
                    conns[topic] = w.add_connection(topic, typ, typestore=store)
                w.write(conns[topic], ns, store.serialize_ros1(msg, typ))
        return
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as w:
        conns = {}
        for ns, topic, typ, msg in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=store)
            w.write(conns[topic], ns, store.serialize_cdr(msg, typ))
