"""Recorded ROS bags in: rosbag2 (mcap, sqlite3) and ROS 1 bags, read with ``rosbags``.

``read_bag`` picks the LaserScan and Odometry topics by type (or by name), converts
every message with the decoders the live ROS source uses (``protocols.ros``), and reads
the lidar's mount from ``/tf_static``, else from ``/tf`` (``protocols.tf``). Where a
bag has several LaserScan topics, the raw one is taken by a stated rule
(``SCAN_TOPIC_RULE``). rosbag2 files written before ROS 2 Iron carry no message
definitions: those of the distribution the user names are used (``ROS_DISTROS``,
Humble by default). How the lidar's driver reports a beam without a return (+inf,
NaN or 0.0) is read off the scans (``no_return_convention``).

A message that cannot be used (malformed, zero beams, a stamp that goes back) is
skipped, counted by reason in ``Bag.skipped`` and logged once per reason; a bag that
cannot be read at all, or has no usable scans or odometry, raises ``DataFormatError``
naming the bag's topics.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from polyswarm.errors import DataFormatError
from polyswarm.slam.scan import LaserScan
from protocols import ros
from protocols.messages import ProtocolError
from protocols.tf import TF, TF_STATIC, MountSources, mount_from_tf

log = logging.getLogger(__name__)

TF_MESSAGE = "tf2_msgs/msg/TFMessage"
BAG_SUFFIXES = (".bag", ".mcap", ".db3")
# the message definitions a bag without its own is read with (rosbags' type stores)
ROS_DISTROS = ("foxy", "galactic", "humble", "iron", "jazzy", "kilted")
DEFAULT_ROS_DISTRO = "humble"
SCAN_TOPIC_RULE = (
    "a topic named 'scan' before any other (the driver's raw scan: /scan before "
    "/stable_scan or /scan_filtered), the shortest such name first"
)


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
    mounts: MountSources  # the mount as /tf_static and /tf give it
    ros2: bool
    skipped: Counter = field(default_factory=Counter)
    scan_topic_note: str = ""  # why this scan topic, when the bag has several
    no_return: str = "inf"  # config.OutOfRange: how the driver reports a beam without return
    no_return_share: float = 0.0  # share of all beams reported so
    definitions: str = "the bag's own"  # the message definitions the bag was read with

    @property
    def mount(self):
        """The mount from tf (/tf_static's, else /tf's), or None."""
        return self.mounts.best()[0]

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


def pick_scan_topic(topics: list[str]) -> tuple[str | None, str]:
    """The raw scan among several LaserScan topics (``SCAN_TOPIC_RULE``), and what to say
    about the choice; None when no topic is named 'scan'."""
    if len(topics) == 1:
        return topics[0], ""
    named = sorted((t for t in topics if t.rstrip("/").rsplit("/", 1)[-1] == "scan"), key=len)
    if not named:
        return None, ""
    others = ", ".join(t for t in topics if t != named[0])
    return named[0], f"scans from {named[0]} ({SCAN_TOPIC_RULE}); not from {others}"


def _typestore(distro: str):
    from rosbags.typesys import Stores, get_typestore

    if distro not in ROS_DISTROS:
        raise DataFormatError(
            f"unknown ROS 2 distribution {distro!r}; known: {', '.join(ROS_DISTROS)}"
        )
    return get_typestore(Stores[f"ROS2_{distro.upper()}"])


def no_return_convention(scans: list[LaserScan]) -> tuple[str, float]:
    """How the driver reports a beam without a return, read off its scans: the most common
    of +inf ("inf"), NaN ("nan") and 0.0 ("zero") among the beams outside the sensor's
    range (REP 117 asks for +inf; the LDS-01 and Neato drivers publish 0.0), "inf" when
    there is none; and the share of all beams so reported."""
    r = np.concatenate([np.asarray(s.ranges, dtype=float) for s in scans]) if scans else []
    if len(r) == 0:
        return "inf", 0.0
    counts = {"inf": int(np.isposinf(r).sum()), "nan": int(np.isnan(r).sum())}
    counts["zero"] = int((r == 0.0).sum())
    best = max(counts, key=counts.get)
    if counts[best] == 0:
        return "inf", 0.0
    return best, counts[best] / len(r)


def read_bag(
    path: str | Path,
    scan_topic: str | None = None,
    odom_topic: str | None = None,
    ros_distro: str = DEFAULT_ROS_DISTRO,
) -> Bag:
    """Every scan and odometry message of a bag, sorted by header stamp; a bag without
    message definitions (rosbag2 before Iron) is read with those of ``ros_distro``."""
    from rosbags.highlevel import AnyReader

    p = Path(path)
    if not p.exists():
        raise DataFormatError(f"bag not found: {p}")
    store = _typestore(ros_distro)
    skipped: Counter = Counter()
    into = ([], [], {TF_STATIC: [], TF: []}, Counter())  # scans, odom, tf, base frames
    try:
        with AnyReader([p], default_typestore=store) as reader:
            conns = reader.connections
            listing = ", ".join(sorted(f"{c.topic} ({c.msgtype})" for c in conns)) or "nothing"
            s_topic, note = _scan_topic(conns, scan_topic, listing)
            o_topic = _pick(conns, ros.ODOMETRY, odom_topic, "odom", listing)
            wanted = [c for c in conns if c.topic in (s_topic, o_topic, TF_STATIC, TF)]
            ros2 = bool(reader.is2)
            own = _has_definitions(reader)
            _read_messages(reader, wanted, (s_topic, o_topic), into, skipped)
    except DataFormatError:
        raise
    except Exception as e:  # rosbags raises many types on bags it cannot open
        raise DataFormatError(f"{p}: cannot read the bag: {type(e).__name__}: {e}") from None
    scans, odom, tf_msgs, base_frames = into
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
    mounts = MountSources(
        _mount(tf_msgs[TF_STATIC], base, scan_frame, skipped),
        _mount(tf_msgs[TF], base, scan_frame, skipped),
    )
    no_return, share = no_return_convention([s[1] for s in scans])
    if note:
        log.info("%s: %s", p, note)
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
        mounts,
        ros2,
        skipped,
        note,
        no_return,
        share,
        "the bag's own" if own else f"ROS 2 {ros_distro}'s (the bag has none)",
    )


def _scan_topic(conns, wanted: str | None, listing: str) -> tuple[str, str]:
    if wanted is not None:
        return _pick(conns, ros.LASER_SCAN, wanted, "scan", listing), ""
    topics = sorted({c.topic for c in conns if c.msgtype == ros.LASER_SCAN})
    if len(topics) > 1:
        chosen, note = pick_scan_topic(topics)
        if chosen is not None:
            return chosen, note
    return _pick(conns, ros.LASER_SCAN, None, "scan", listing), ""


def _has_definitions(reader) -> bool:
    """Whether the bag carried its own message definitions (ROS 1 bags always do)."""
    if not reader.is2:
        return True
    return any(getattr(c, "msgdef", None) and c.msgdef.data for c in reader.connections)


def _mount(msgs: list, base: str, scan_frame: str, skipped: Counter):
    if not msgs:
        return None
    try:
        return mount_from_tf(msgs, base, scan_frame)
    except DataFormatError as e:  # a cycle, a broken quaternion: that topic says nothing
        _skip(skipped, "an unusable tf tree", str(e))
        return None


def _read_messages(reader, wanted, topics, into, skipped: Counter) -> None:
    """Append the bag's messages to ``into`` = (scans, odom, tf messages by topic, base
    frames)."""
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
        if conn.topic in tf_msgs:
            if conn.msgtype == TF_MESSAGE:
                tf_msgs[conn.topic].append(msg)
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
