"""Stage 1 of PolySLAM: a laser scan to points in the sensor frame (thesis 3.3-3.4).

Invalid beams (infinite, NaN, shorter than the sensor's minimum or at/beyond its
maximum range) become points at a safe short range and are flagged invalid: the space
the robot occupies is known to be free, so they add explored space and frontier
vectors, never obstacles.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, eq=False)
class LaserScan:
    """One sweep: beam ``k`` at ``angle_min + k * angle_increment`` (radians, CCW)."""

    ranges: np.ndarray  # metres; inf = no return, NaN = dropout
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    stamp: float = 0.0  # seconds

    @property
    def angles(self) -> np.ndarray:
        return self.angle_min + self.angle_increment * np.arange(len(self.ranges))

    @property
    def fov(self) -> float:
        return abs(self.angle_increment) * max(len(self.ranges) - 1, 0)


@dataclass(frozen=True, eq=False)
class ScanPoints:
    xy: np.ndarray  # (n, 2) in the robot frame, beam order (counter-clockwise)
    valid: np.ndarray  # (n,) bool: a real return from an obstacle
    full_circle: bool  # beams cover 360 degrees: the polygon closes without the centre
    origin: np.ndarray = field(default_factory=lambda: np.zeros(2))  # sensor, robot frame


def scan_to_points(
    scan: LaserScan,
    frontier_range_m: float = 0.2,
    mount: tuple[float, float, float, bool] = (0.0, 0.0, 0.0, False),
) -> ScanPoints:
    """Points of a scan in the robot frame; ``mount`` = (x, y, yaw, upside_down)."""
    mx, my, myaw, flipped = mount
    r = np.asarray(scan.ranges, dtype=float)
    a = scan.angles
    if flipped:  # an upside-down lidar sweeps clockwise as seen from above
        a = -a
    a = a + myaw
    order = np.argsort(a, kind="stable")  # beam order counter-clockwise
    r, a = r[order], a[order]
    valid = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max)
    rr = np.where(valid, r, min(frontier_range_m, 0.5 * scan.range_max))
    xy = np.stack([mx + rr * np.cos(a), my + rr * np.sin(a)], axis=1)
    full = abs(scan.angle_increment) * len(r) >= 2 * np.pi - 1e-6
    return ScanPoints(xy, valid, bool(full), np.array([mx, my], dtype=float))
