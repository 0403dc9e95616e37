"""Stage 5 of PolySLAM: the keyframe polygon (thesis 3.4).

The aligned scan points are joined in beam order and closed through the sensor
centre. A vector between two real returns is an obstacle when they are close enough to
lie on one surface: no farther apart than ``max_gap_m``, or than ``gap_beams`` times the
beam spacing at their range (far points of a 1-degree lidar are 0.5 m apart on a wall
30 m away, more on a wall seen at a grazing angle). Every other vector (to or from an
invalid beam, across a gap, or to the sensor centre) is a frontier. Points taken in
angular order around the centre make a star-shaped, hence simple, polygon.

``KeyframeSelector`` is stage 2: when a scan becomes a keyframe (travel or turn).
"""

from __future__ import annotations

import numpy as np

from polyswarm.polymap import Ring, TypedPolygon, VectorType
from polyswarm.se2 import relative
from polyswarm.slam.scan import ScanPoints


def transform(xy: np.ndarray, pose) -> np.ndarray:
    x, y, th = pose
    c, s = np.cos(th), np.sin(th)
    return np.asarray(xy) @ np.array([[c, s], [-s, c]]) + np.array([x, y])


def vector_types(
    valid: np.ndarray,
    xy: np.ndarray,
    max_gap_m: float,
    closed: bool,
    origin=(0.0, 0.0),
    gap_beams: float = 0.0,
) -> np.ndarray:
    """Type of vector k (point k to point k+1); for open scans the last one is unused."""
    nxt = np.roll(xy, -1, axis=0)
    gap = np.hypot(*(nxt - xy).T)
    limit = np.full(len(xy), max_gap_m)
    if gap_beams > 0:
        rel = xy - np.asarray(origin)
        r = np.hypot(rel[:, 0], rel[:, 1])
        ang = np.arctan2(rel[:, 1], rel[:, 0])
        step = np.abs((np.roll(ang, -1) - ang + np.pi) % (2 * np.pi) - np.pi)
        limit = np.maximum(limit, gap_beams * np.maximum(r, np.roll(r, -1)) * step)
    ok = valid & np.roll(valid, -1) & (gap <= limit)
    t = np.where(ok, VectorType.OBSTACLE, VectorType.FRONTIER).astype(np.uint8)
    if not closed:
        t[-1] = VectorType.FRONTIER
    return t


def keyframe_polygon(
    points: ScanPoints, pose, max_gap_m: float = 0.5, gap_beams: float = 0.0
) -> TypedPolygon:
    """The keyframe polygon in the world frame for a robot at ``pose`` (x, y, theta)."""
    xy = transform(points.xy, pose)
    types = vector_types(
        points.valid, points.xy, max_gap_m, points.full_circle, points.origin, gap_beams
    )
    if not points.full_circle:
        # last point -> sensor centre -> first point, both frontiers
        xy = np.vstack([xy, transform(points.origin[None, :], pose)])
        types = np.append(types, VectorType.FRONTIER).astype(np.uint8)
    return TypedPolygon(Ring(xy, types))


class KeyframeSelector:
    """Stage 2: a new keyframe after enough travel or rotation (odometry)."""

    def __init__(self, distance_m: float, angle_rad: float) -> None:
        self.distance_m, self.angle_rad = distance_m, angle_rad
        self.last: np.ndarray | None = None

    def due(self, odom: np.ndarray) -> bool:
        if self.last is None:
            return True
        d = relative(self.last, odom)
        return bool(np.hypot(d[0], d[1]) >= self.distance_m or abs(d[2]) >= self.angle_rad)

    def moved(self, odom: np.ndarray, share: float) -> bool:
        """Has the robot moved ``share`` of the way to the next keyframe?"""
        if self.last is None:
            return True
        d = relative(self.last, odom)
        return bool(
            np.hypot(d[0], d[1]) >= share * self.distance_m or abs(d[2]) >= share * self.angle_rad
        )

    def mark(self, odom: np.ndarray) -> None:
        self.last = np.array(odom, dtype=float)
