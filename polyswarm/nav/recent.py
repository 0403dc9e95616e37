"""The returns of the last few seconds around the robot, for its local controller.

A low-cost lidar sees little of a black or glass wall: the fitted LDS-01 model returns
about 5 % of the beams that meet one, in runs along the sweep, and nothing closer than
its 0.12 m minimum range. A controller that avoids only the current scan drives into
such a wall (TurtleBot3s on the office touched one five times in 300 simulated
seconds). Scan after scan, the few returns a dark wall does give land in different
places; remembered for a few seconds in the odometry frame (smooth over seconds, unlike
the SLAM pose that jumps at a correction), they outline the wall densely enough that no
arc of the controller passes between them.

    recent = RecentReturns()
    recent.add(now_s, odom_pose, returns_robot_xy)     # every scan, after forgetting
    obstacles = recent.points(now_s, odom_pose)        # robot frame, for the controller

A remembered point that a later scan sees through (a robot or a person gone by) is
forgotten, as a costmap's obstacle layer clears along its rays (``seen_through``).
"""

from __future__ import annotations

import math

import numpy as np

from polyswarm.se2 import transform_points

RECENT_KEEP_S = 4.0  # 20 scans at 5 Hz: a dark wall's 5 % of returns mark 64 % of its beams
RECENT_RANGE_M = 1.5  # what the controller's arcs (1.2 s at 0.5 m/s, plus a radius) reach
RECENT_VOXEL_M = 0.03  # one point per square this wide: about a return's noise
# a point is seen through when every return within this bearing of it is farther by
# CLEAR_MARGIN_M: wide enough to hold two beams of a 1-degree lidar (TurtleBot3,
# RPLIDAR), narrow enough that a wall beside it is not in it
CLEAR_HALF_ANGLE_RAD = math.radians(1.0)
CLEAR_MARGIN_M = 0.1  # beyond the point by more than a return's noise (2-6 cm)


def seen_through(points_xy: np.ndarray, returns_xy: np.ndarray, origin_xy) -> np.ndarray:
    """Which ``points_xy`` (k, 2) a scan with returns ``returns_xy`` (n, 2), taken from
    ``origin_xy`` (all in one frame, metres), sees through: it has returns within
    ``CLEAR_HALF_ANGLE_RAD`` of the point's bearing and all of them lie at least
    ``CLEAR_MARGIN_M`` beyond it. A bearing without returns says nothing."""
    pts = np.asarray(points_xy, dtype=float).reshape(-1, 2)
    ret = np.asarray(returns_xy, dtype=float).reshape(-1, 2)
    if not len(pts) or not len(ret):
        return np.zeros(len(pts), dtype=bool)
    here = np.asarray(origin_xy, dtype=float)[:2]
    rel = ret - here
    bearing, rng = np.arctan2(rel[:, 1], rel[:, 0]), np.hypot(rel[:, 0], rel[:, 1])
    order = np.argsort(bearing)
    bearing, rng = bearing[order], rng[order]
    # the bearings once more on either side: a point near +-pi sees both ends
    bearing = np.concatenate([bearing - 2 * math.pi, bearing, bearing + 2 * math.pi])
    rng = np.concatenate([rng, rng, rng])
    mem = pts - here
    mb, md = np.arctan2(mem[:, 1], mem[:, 0]), np.hypot(mem[:, 0], mem[:, 1])
    lo = np.searchsorted(bearing, mb - CLEAR_HALF_ANGLE_RAD, side="left")
    hi = np.searchsorted(bearing, mb + CLEAR_HALF_ANGLE_RAD, side="right")
    # the nearest return of each point's bearings: rng[lo:hi].min(), all at once
    # (reduceat over lo, hi pairs; an inf at the end stands for "no more returns")
    pairs = np.column_stack([lo, hi]).ravel()
    nearest = np.minimum.reduceat(np.append(rng, np.inf), pairs)[::2]
    return (hi > lo) & (nearest >= md + CLEAR_MARGIN_M)


class RecentReturns:
    """Returns of the last ``keep_s`` seconds within ``range_m`` of the robot, one per
    ``voxel_m`` square, in the odometry frame."""

    def __init__(
        self,
        keep_s: float = RECENT_KEEP_S,
        range_m: float = RECENT_RANGE_M,
        voxel_m: float = RECENT_VOXEL_M,
    ) -> None:
        self.keep_s, self.range_m, self.voxel_m = keep_s, range_m, voxel_m
        self._xy = np.zeros((0, 2))  # odometry frame
        self._t = np.zeros(0)

    def __len__(self) -> int:
        return len(self._xy)

    def add(self, now_s: float, odom_pose, returns_xy: np.ndarray) -> None:
        """One scan: ``returns_xy`` (n, 2) its returns in the robot frame at ``odom_pose``
        (x, y, heading in the odometry frame). Forgets what this scan sees through and
        what is older than ``keep_s`` or beyond ``range_m``; remembers the close returns."""
        ret = np.asarray(returns_xy, dtype=float).reshape(-1, 2)
        world = transform_points(odom_pose, ret)
        here = np.asarray(odom_pose, dtype=float)[:2]
        keep = (now_s - self._t <= self.keep_s) & (np.hypot(*(self._xy - here).T) <= self.range_m)
        keep &= ~seen_through(self._xy, world, here)
        close = np.hypot(ret[:, 0], ret[:, 1]) <= self.range_m
        xy = np.concatenate([self._xy[keep], world[close]])
        t = np.concatenate([self._t[keep], np.full(int(close.sum()), float(now_s))])
        # one point per voxel, the newest (np.unique keeps the first of each key)
        keys = np.floor(xy / self.voxel_m).astype(np.int64)
        _, first = np.unique(keys[::-1], axis=0, return_index=True)
        pick = np.sort(len(xy) - 1 - first)
        self._xy, self._t = xy[pick], t[pick]

    def points(self, now_s: float, odom_pose) -> np.ndarray:
        """The remembered returns no older than ``keep_s``, (k, 2) in the robot frame at
        ``odom_pose``."""
        xy = self._xy[now_s - self._t <= self.keep_s]
        x, y, th = (float(v) for v in odom_pose)
        c, s = math.cos(th), math.sin(th)
        d = xy - (x, y)
        return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])

    def clear(self) -> None:
        self._xy, self._t = np.zeros((0, 2)), np.zeros(0)
