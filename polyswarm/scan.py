"""Stage 1 of PolySLAM: a laser scan to points in the sensor frame (thesis 3.3-3.4).

Invalid beams (infinite, NaN, shorter than the sensor's minimum or at/beyond its
maximum range) become points at a safe short range and are flagged invalid: the space
the robot occupies is known to be free, so they add explored space and frontier
vectors, never obstacles.
"""

from __future__ import annotations

from dataclasses import dataclass

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
    xy: np.ndarray  # (n, 2) in the sensor frame, beam order (counter-clockwise)
    valid: np.ndarray  # (n,) bool: a real return from an obstacle
    full_circle: bool  # beams cover 360 degrees: the polygon closes without the centre


def scan_to_points(scan: LaserScan, frontier_range_m: float = 0.2) -> ScanPoints:
    r = np.asarray(scan.ranges, dtype=float)
    a = scan.angles
    if scan.angle_increment < 0:  # make beam order counter-clockwise
        r, a = r[::-1], a[::-1]
    valid = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max)
    rr = np.where(valid, r, min(frontier_range_m, 0.5 * scan.range_max))
    xy = np.stack([rr * np.cos(a), rr * np.sin(a)], axis=1)
    full = abs(scan.angle_increment) * len(r) >= 2 * np.pi - 1e-6
    return ScanPoints(xy, valid, bool(full))
