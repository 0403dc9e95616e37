"""Stage 1 of PolySLAM: a laser scan to points in the sensor frame (thesis 3.3-3.4).

Invalid beams become points flagged invalid, so they add explored space and frontier
vectors, never obstacles:

* a dropout (NaN, or shorter than the sensor's minimum range) becomes a point at a safe
  short range (thesis 3.4): the space the robot occupies is known to be free;
* a beam with no return within the sensor's maximum range (infinite, or at or beyond
  it) passed through free space: it becomes a point ``no_return_free_m`` out (what
  Cartographer calls ``missing_data_ray_length``). At the thesis' short range instead,
  a robot turning on the spot leaves the same thin wedges of unknown space at the same
  bearings in every keyframe, all meeting at the sensor: a robot standing in their apex
  had no room to plan from (the 1-robot maze start).
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


def beam_angles(scan: LaserScan, mount: tuple[float, float, float, bool]) -> np.ndarray:
    """Each beam's direction in the robot frame (radians, in the scan's beam order) for a
    lidar at ``mount`` = (x, y, yaw, upside_down)."""
    a = -scan.angles if mount[3] else scan.angles  # upside down: sweeps clockwise
    return a + mount[2]


def scan_to_points(
    scan: LaserScan,
    frontier_range_m: float = 0.2,
    mount: tuple[float, float, float, bool] = (0.0, 0.0, 0.0, False),
    no_return_free_m: float | None = None,
) -> ScanPoints:
    """Points of a scan in the robot frame; ``mount`` = (x, y, yaw, upside_down).

    ``no_return_free_m`` (metres; default ``frontier_range_m``) is where a beam with no
    return within the maximum range ends; never beyond half the maximum range."""
    mx, my = mount[:2]
    r = np.asarray(scan.ranges, dtype=float)
    a = beam_angles(scan, mount)
    order = np.argsort(a, kind="stable")  # beam order counter-clockwise
    r, a = r[order], a[order]
    valid = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max)
    no_return = r >= scan.range_max  # +inf included; NaN compares false
    free_m = frontier_range_m if no_return_free_m is None else no_return_free_m
    half = 0.5 * scan.range_max
    rr = np.where(valid, r, np.where(no_return, min(free_m, half), min(frontier_range_m, half)))
    xy = np.stack([mx + rr * np.cos(a), my + rr * np.sin(a)], axis=1)
    full = abs(scan.angle_increment) * len(r) >= 2 * np.pi - 1e-6
    return ScanPoints(xy, valid, bool(full), np.array([mx, my], dtype=float))
