"""The lidar's mount on the robot, from tf (tf2_msgs/TFMessage) or the configuration.

A robot says where its lidar sits with a static transform from its base frame to the
scan's frame. ROS 2 publishes it on ``/tf_static``; many ROS 1 setups publish it on
``/tf``, again and again, beside the moving odom -> base transform. Both are read; the
configuration's ``[slam.mount]``, when set, wins over both:

    mounts = MountSources(static=mount_from_tf(static_msgs, base, scan),
                          dynamic=mount_from_tf(tf_msgs, base, scan))
    mount, source = choose_mount(cfg.slam.mount, mounts, "robot.bag")

Where the sources disagree (a bag may carry two mounts), which one was used is said.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from polyswarm.errors import DataFormatError

log = logging.getLogger(__name__)

TF_STATIC = "/tf_static"
TF = "/tf"
SAME_MOUNT_M = 0.01  # mounts this close (and SAME_MOUNT_RAD) are the same mount
SAME_MOUNT_RAD = 0.02


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

    def same_as(self, other) -> bool:
        """Within SAME_MOUNT_M and SAME_MOUNT_RAD of ``other`` (a Mount2D or LidarMount)."""
        dyaw = math.remainder(self.yaw_rad - other.yaw_rad, 2 * math.pi)
        return (
            abs(self.x_m - other.x_m) <= SAME_MOUNT_M
            and abs(self.y_m - other.y_m) <= SAME_MOUNT_M
            and abs(dyaw) <= SAME_MOUNT_RAD
            and self.upside_down == other.upside_down
        )

    def describe(self) -> str:
        flip = ", upside down" if self.upside_down else ""
        return f"x {self.x_m:+.3f} m, y {self.y_m:+.3f} m, yaw {self.yaw_rad:+.3f} rad{flip}"


@dataclass(frozen=True)
class MountSources:
    """The mount as each tf topic gives it (None: that topic does not connect the frames)."""

    static: Mount2D | None = None  # from /tf_static
    dynamic: Mount2D | None = None  # from /tf (a static transform republished there)

    def best(self) -> tuple[Mount2D | None, str]:
        """/tf_static's, else /tf's; and the topic it came from ("" for none)."""
        if self.static is not None:
            return self.static, TF_STATIC
        if self.dynamic is not None:
            return self.dynamic, TF
        return None, ""

    def disagreement(self) -> str:
        """A sentence when /tf_static and /tf give different mounts, else ""."""
        if self.static is None or self.dynamic is None or self.static.same_as(self.dynamic):
            return ""
        return (
            f"/tf_static and /tf disagree on the lidar mount: {self.static.describe()} "
            f"against {self.dynamic.describe()}; using /tf_static's"
        )


def choose_mount(configured, found: MountSources | Mount2D | None, where: str):
    """The mount to use (a ``config.LidarMount``) and where it came from ("config",
    "/tf_static", "/tf" or "default"): the config's when it sets one (anything but the
    default), else tf's (``MountSources.best``), else the default (said once in the log:
    a wrong mount silently gives a bad map)."""
    from polyswarm.config import LidarMount

    if isinstance(found, Mount2D):
        found = MountSources(static=found)
    tf_mount, topic = found.best() if found is not None else (None, "")
    if configured != LidarMount():
        if tf_mount is not None and not tf_mount.same_as(configured):
            log.warning("%s: the config's [slam.mount] overrides %s's %s", where, topic, tf_mount)
        return configured, "config"
    if tf_mount is not None:
        note = found.disagreement()
        if note:
            log.warning("%s: %s", where, note)
        log.info(
            "%s: lidar mount from %s (%s -> %s): %s",
            where,
            topic,
            tf_mount.base_frame,
            tf_mount.scan_frame,
            tf_mount.describe(),
        )
        m = tf_mount
        return LidarMount(m.x_m, m.y_m, m.yaw_rad, m.upside_down), topic
    log.warning(
        "%s: no lidar mount in tf or in the config ([slam.mount]): assuming the lidar at "
        "the robot's origin, facing forward, upright",
        where,
    )
    return configured, "default"


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
    tr = [float(t.translation.x), float(t.translation.y), float(t.translation.z)]
    if not all(math.isfinite(v) for v in tr):
        raise DataFormatError("tf: translation is not finite")
    m[:3, 3] = tr
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
    """The scan frame in the base frame, from tf2_msgs/TFMessage messages (the latest
    transform of each child frame), as a 2D mount: a lidar upside down (rolled or
    pitched by pi) sweeps clockwise, which ``upside_down`` says and the yaw of its x axis
    completes. None when the two frames are not connected."""
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
