"""Recorded ROS bags in: rosbag2 (mcap, sqlite3) and ROS 1 bags, read with ``rosbags``.

``read_bag`` picks the LaserScan and Odometry topics by type (or by name), converts
every message with the decoders the live ROS source uses (``protocols.ros``), and reads
the lidar's mount from ``/tf_static`` (``mount_from_tf``). A message that cannot be
used (malformed, zero beams, a stamp that goes back) is skipped, counted by reason in
``Bag.skipped`` and logged once per reason; a bag that cannot be read at all, or has no
usable scans or odometry, raises ``DataFormatError`` naming the bag's topics.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from polyswarm.errors import DataFormatError
from polyswarm.slam.scan import LaserScan
from protocols import ros
from protocols.messages import ProtocolError

log = logging.getLogger(__name__)

TF_STATIC = "/tf_static"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
BAG_SUFFIXES = (".bag", ".mcap", ".db3")


@dataclass(frozen=True)
class Mount2D:
    """The lidar on the robot, as polyswarm uses it: position (metres), yaw (radians),
    and whether it is upside down (its beams then run clockwise seen from above)."""

    x_m: float
    y_m: float
    yaw_rad: float
    upside_down: bool
    base_frame: str = ""
    scan_frame: str = ""


@dataclass
class Bag:
    path: str
    scan_topic: str
    odom_topic: str
    scans: list[LaserScan]
    scan_raw: list[bytes | None]  # each scan's CDR as recorded (ROS 2 bags), else None
    odometry: np.ndarray  # (k, 4): stamp (s), x, y, yaw in the odometry frame
    odom_raw: list[bytes | None]  # each odometry message's CDR as recorded, or None
    scan_frame: str
    base_frame: str  # the odometry's child frame
    mount: Mount2D | None  # from /tf_static, when the bag has it
    ros2: bool
    skipped: Counter = field(default_factory=Counter)

    @property
    def duration_s(self) -> float:
        return self.scans[-1].stamp - self.scans[0].stamp if len(self.scans) > 1 else 0.0


def is_bag(path: str | Path) -> bool:
    """A ROS 1 bag, an mcap or sqlite3 file, or a rosbag2 folder (with metadata.yaml)."""
    p = Path(path)
    return p.suffix in BAG_SUFFIXES or (p.is_dir() and (p / "metadata.yaml").exists())


def _skip(skipped: Counter, reason: str, detail: str = "") -> None:
    if not skipped[reason]:
        log.warning(
            "bag: skipping %s%s (counted; logged once)", reason, f": {detail}" if detail else ""
        )
    skipped[reason] += 1


def _pick(connections, msgtype: str, wanted: str | None, what: str, listing: str) -> str:
    topics = sorted({c.topic for c in connections if c.msgtype == msgtype})
    if wanted is not None:
        if wanted not in {c.topic for c in connections}:
            raise DataFormatError(f"no topic {wanted!r} in the bag; it has: {listing}")
        return wanted
    if not topics:
        raise DataFormatError(f"no {msgtype} topic ({what}) in the bag; it has: {listing}")
    if len(topics) > 1:
        raise DataFormatError(
            f"several {msgtype} topics: {', '.join(topics)}; pick one with --{what}-topic"
        )
    return topics[0]


def read_bag(path: str | Path, scan_topic: str | None = None, odom_topic: str | None = None) -> Bag:
    """Every scan and odometry message of a bag, sorted by header stamp."""
    from rosbags.highlevel import AnyReader

    p = Path(path)
    if not p.exists():
        raise DataFormatError(f"bag not found: {p}")
    skipped: Counter = Counter()
    scans: list[tuple[float, LaserScan, bytes | None, str]] = []
    odom: list[tuple] = []  # (stamp, x, y, yaw, raw CDR or None)
    base_frames: Counter = Counter()
    tf_msgs = []
    try:
        with AnyReader([p]) as reader:
            conns = reader.connections
            listing = ", ".join(sorted(f"{c.topic} ({c.msgtype})" for c in conns)) or "nothing"
            s_topic = _pick(conns, ros.LASER_SCAN, scan_topic, "scan", listing)
            o_topic = _pick(conns, ros.ODOMETRY, odom_topic, "odom", listing)
            wanted = [c for c in conns if c.topic in (s_topic, o_topic, TF_STATIC)]
            ros2 = bool(reader.is2)
            _read_messages(
                reader, wanted, (s_topic, o_topic), (scans, odom, tf_msgs, base_frames), skipped
            )
    except DataFormatError:
        raise
    except Exception as e:  # rosbags raises many types on bags it cannot open
        raise DataFormatError(f"{p}: cannot read the bag: {type(e).__name__}: {e}") from None
    if not scans:
        raise DataFormatError(f"{p}: no usable scans on {s_topic} (skipped: {dict(skipped)})")
    if len(odom) < 2:
        raise DataFormatError(
            f"{p}: no usable odometry on {o_topic} ({len(odom)} messages; skipped: {dict(skipped)})"
        )
    scans = _monotonic(sorted(scans, key=lambda s: s[0]), skipped, "scan")
    odom = _monotonic(sorted(odom, key=lambda o: o[0]), skipped, "odometry")
    od = np.array([o[:4] for o in odom], dtype=float)
    scan_frame = Counter(s[3] for s in scans).most_common(1)[0][0]
    base = base_frames.most_common(1)[0][0] if base_frames else ""
    mount = mount_from_tf(tf_msgs, base, scan_frame) if tf_msgs else None
    return Bag(
        str(p),
        s_topic,
        o_topic,
        [s[1] for s in scans],
        [s[2] for s in scans],
        od,
        [o[4] for o in odom],
        scan_frame,
        base,
        mount,
        ros2,
        skipped,
    )


def _read_messages(reader, wanted, topics, into, skipped: Counter) -> None:
    """Append the bag's messages to ``into`` = (scans, odom, tf messages, base frames)."""
    s_topic, o_topic = topics
    scans, odom, tf_msgs, base_frames = into
    ros2 = bool(reader.is2)
    messages = reader.messages(connections=wanted)
    while True:
        try:
            conn, t_ns, raw = next(messages)
        except StopIteration:
            return
        except Exception as e:  # a truncated or corrupt chunk: keep what came before it
            _skip(skipped, "the rest of the bag (unreadable)", f"{type(e).__name__}: {e}")
            return
        try:
            msg = reader.deserialize(raw, conn.msgtype)
        except Exception as e:
            _skip(skipped, f"malformed {conn.msgtype}", f"{type(e).__name__}: {e}")
            continue
        if conn.topic == TF_STATIC:
            tf_msgs.append(msg)
            continue
        try:
            if conn.topic == s_topic:
                scan = ros.laserscan_from_msg(msg)
                stamp = scan.stamp if scan.stamp > 0 else t_ns * 1e-9
                if stamp != scan.stamp:
                    scan = _restamp(scan, stamp)
                scans.append((stamp, scan, bytes(raw) if ros2 else None, msg.header.frame_id))
            elif conn.topic == o_topic:
                stamp, pose, _ = ros.odometry_from_msg(msg)
                stamp = stamp if stamp > 0 else t_ns * 1e-9
                odom.append((stamp, *(float(v) for v in pose), bytes(raw) if ros2 else None))
                base_frames[msg.child_frame_id] += 1
        except ProtocolError as e:
            _skip(skipped, f"unusable {conn.msgtype}", str(e))


def _restamp(scan: LaserScan, stamp: float) -> LaserScan:
    from dataclasses import replace

    return replace(scan, stamp=stamp)


def _monotonic(items: list, skipped: Counter, what: str) -> list:
    """Items (sorted by stamp) without repeated stamps (counted)."""
    out = []
    for it in items:
        if out and it[0] <= out[-1][0]:
            _skip(skipped, f"{what} with a repeated stamp")
            continue
        out.append(it)
    return out


def choose_mount(configured, from_tf: Mount2D | None, where: str):
    """The mount to use (a ``config.LidarMount``) and where it came from: the config's
    when it sets one (anything but the default), else the one from tf, else the default
    (said once in the log: a wrong mount silently gives a bad map)."""
    from polyswarm.config import LidarMount

    if configured != LidarMount():
        if from_tf is not None and not _same_mount(configured, from_tf):
            log.warning("%s: the config's [slam.mount] overrides tf's %s", where, from_tf)
        return configured, "config"
    if from_tf is not None:
        log.info(
            "%s: lidar mount from tf (%s -> %s): %s",
            where,
            from_tf.base_frame,
            from_tf.scan_frame,
            from_tf,
        )
        m = from_tf
        return LidarMount(m.x_m, m.y_m, m.yaw_rad, m.upside_down), "tf"
    log.warning(
        "%s: no lidar mount in tf or in the config ([slam.mount]): assuming the lidar at "
        "the robot's origin, facing forward, upright",
        where,
    )
    return configured, "default"


def _same_mount(cfg, tf: Mount2D, tol_m: float = 0.01, tol_rad: float = 0.02) -> bool:
    dyaw = math.remainder(cfg.yaw_rad - tf.yaw_rad, 2 * math.pi)
    return (
        abs(cfg.x_m - tf.x_m) <= tol_m
        and abs(cfg.y_m - tf.y_m) <= tol_m
        and abs(dyaw) <= tol_rad
        and cfg.upside_down == tf.upside_down
    )


# --- the lidar's mount from tf ------------------------------------------------------------


def _matrix(t) -> np.ndarray:
    """A geometry_msgs/Transform as a 4x4 homogeneous matrix."""
    q = t.rotation
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not (math.isfinite(n) and n > 0.5):
        raise DataFormatError("tf: rotation is not a unit quaternion")
    x, y, z, w = x / n, y / n, z / n, w / n
    m = np.eye(4)
    m[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    m[:3, 3] = [float(t.translation.x), float(t.translation.y), float(t.translation.z)]
    return m


def _to_root(frame: str, parent: dict[str, tuple[str, np.ndarray]]) -> tuple[str, np.ndarray]:
    """(root frame, transform root <- frame) following the tf tree upwards."""
    m, seen = np.eye(4), {frame}
    while frame in parent:
        frame, step = parent[frame][0], parent[frame][1]
        m = step @ m
        if frame in seen:
            raise DataFormatError(f"tf: a cycle through {frame!r}")
        seen.add(frame)
    return frame, m


def mount_from_tf(tf_messages, base_frame: str, scan_frame: str) -> Mount2D | None:
    """The scan frame in the base frame, from tf2_msgs/TFMessage messages (``/tf_static``),
    as a 2D mount: a lidar upside down (rolled or pitched by pi) sweeps clockwise, which
    ``upside_down`` says and the yaw of its x axis completes. None when the two frames
    are not connected."""
    parent: dict[str, tuple[str, np.ndarray]] = {}
    for msg in tf_messages:
        for tr in msg.transforms:
            child = tr.child_frame_id.lstrip("/")
            parent[child] = (tr.header.frame_id.lstrip("/"), _matrix(tr.transform))
    base, scan = base_frame.lstrip("/"), scan_frame.lstrip("/")
    if not base or not scan:
        return None
    if base == scan:
        return Mount2D(0.0, 0.0, 0.0, False, base, scan)
    root_b, m_b = _to_root(base, parent)
    root_s, m_s = _to_root(scan, parent)
    if root_b != root_s:
        return None
    m = np.linalg.inv(m_b) @ m_s  # base <- scan
    r = m[:3, :3]
    yaw = math.atan2(r[1, 0], r[0, 0])
    return Mount2D(float(m[0, 3]), float(m[1, 3]), yaw, bool(r[2, 2] < 0), base, scan)
