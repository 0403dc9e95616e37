"""Stage 1 of PolySLAM: a laser scan to points in the robot frame (thesis 3.3-3.4).

Drivers report a beam without a valid return in three ways (``out_of_range``): +inf
(REP 117; rplidar_ros), NaN, or 0.0 (the TurtleBot3 LDS-01 driver, which also reports
its dropouts so). Beams are classified before they become points:

* a **return**: finite, within [range_min, range_max);
* **no return**: +inf or at least range_max, or a run of at least ``NO_RETURN_RUN``
  invalid beams reported the driver's no-return way. The beam crossed free space: it
  becomes a point ``no_return_free_m`` out, or at ``NO_RETURN_SHARE`` of the maximum
  range if that is less (what Cartographer calls ``missing_data_ray_length``). At the
  thesis' short range instead, a robot turning on the spot leaves the same thin wedges of
  unknown space at the same bearings in every keyframe, all meeting at the sensor: a
  robot standing in their apex had no room to plan from (the 1-robot maze start);
* a **dropout**: a shorter run of invalid beams between returns. The neighbours say a
  surface is there, so the beams are left out and the polygon joins their neighbours
  (an RPLIDAR's failed reading is +inf, the same as no return: read as free space it
  cut a spike through the wall);
* **unknown**: anything else invalid (NaN from a +inf driver, a run between returns
  within a few times the minimum range: something too close to measure) becomes a point
  at the safe short range ``frontier_range_m`` (thesis 3.4).

A spinning lidar takes its beams over the sweep (``LaserScan.time_increment``); with the
robot's motion during it (``motion``), every point is moved into the robot frame at the
sweep's end (de-skewing), as the sensor's own driver cannot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

NO_RETURN_RUN = 3  # beams: shorter runs of invalid beams between returns are dropouts
# a run of invalid beams between returns closer than this many times the sensor's
# minimum range is something too close to measure (a TurtleBot3 brushing a wall: the
# LDS-01 reads below 0.12 m as 0.0, and taken as "no return" its beams cut 2.8 m of free
# space through the wall; walls vanished and the furnished world ended at 81 %)
NEAR_RUN_SHARE = 3.0
# a no-return beam is trusted as free space to this share of the maximum range (the far
# end of a sensor's range is where its misses are least certain)
NO_RETURN_SHARE = 0.8
# returns farther apart than this (plus BLOB_JUMP_SHARE of their range) from their
# neighbour belong to different objects (``isolated_blobs``); a robot is a blob that
# stands at least BLOB_GAP_M in front of what the beams beside it see, within
# BLOB_RANGE_M (robots of unknown frames 0.5-2.2 m apart pulled ICP along corridors: 14
# of 15 pose jumps of 0.2-0.5 m in 100 launches at unknown starts; none in 50 since)
BLOB_JUMP_M = 0.1
BLOB_JUMP_SHARE = 0.03
BLOB_GAP_M = 0.3
BLOB_RANGE_M = 5.0


@dataclass(frozen=True, eq=False)
class LaserScan:
    """One sweep: beam ``k`` at ``angle_min + k * angle_increment`` (radians, CCW), taken
    at ``stamp + k * time_increment`` (seconds; 0: all beams at ``stamp``), as in
    sensor_msgs/LaserScan."""

    ranges: np.ndarray  # metres; how a beam without a return reads depends on the driver
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    stamp: float = 0.0  # seconds: the first beam's time
    time_increment: float = 0.0
    scan_time: float = 0.0  # seconds between scans (informative)

    @property
    def angles(self) -> np.ndarray:
        return self.angle_min + self.angle_increment * np.arange(len(self.ranges))

    @property
    def fov(self) -> float:
        return abs(self.angle_increment) * max(len(self.ranges) - 1, 0)

    @property
    def end_stamp(self) -> float:
        """The last beam's time."""
        return self.stamp + self.time_increment * max(len(self.ranges) - 1, 0)

    @property
    def beam_stamps(self) -> np.ndarray:
        return self.stamp + self.time_increment * np.arange(len(self.ranges))


@dataclass(frozen=True, eq=False)
class ScanPoints:
    xy: np.ndarray  # (n, 2) in the robot frame, counter-clockwise around the sensor
    valid: np.ndarray  # (n,) bool: a real return from an obstacle
    full_circle: bool  # beams cover 360 degrees: the polygon closes without the centre
    origin: np.ndarray = field(default_factory=lambda: np.zeros(2))  # sensor, robot frame
    # (n,) bool: a beam without a return, cut where free space is trusted to reach
    no_return: np.ndarray | None = None


def beam_angles(scan: LaserScan, mount: tuple[float, float, float, bool]) -> np.ndarray:
    """Each beam's direction in the robot frame (radians, in the scan's beam order) for a
    lidar at ``mount`` = (x, y, yaw, upside_down)."""
    a = -scan.angles if mount[3] else scan.angles  # upside down: sweeps clockwise
    return a + mount[2]


def classify(scan: LaserScan, out_of_range: str = "inf") -> tuple[np.ndarray, ...]:
    """(valid, no_return, dropout) masks of the beams; the rest is unknown."""
    r = np.asarray(scan.ranges, dtype=float)
    valid = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max) & (r > 0)
    far = (r >= scan.range_max) & ~np.isnan(r)  # +inf, or a reading at the range's end
    # the driver's own way of saying "no return" (which, for 0.0, is also a dropout)
    said = {"inf": np.isposinf(r), "nan": np.isnan(r), "zero": r == 0.0}[out_of_range] | far
    circular = scan.fov >= 2 * np.pi - 1.5 * abs(scan.angle_increment)
    dropout = np.zeros(len(r), dtype=bool)
    near = np.zeros(len(r), dtype=bool)
    near_m = NEAR_RUN_SHARE * max(scan.range_min, 0.05)
    for run, left, right in _invalid_runs(~valid, circular):
        if left is None or right is None:
            continue
        if len(run) < NO_RETURN_RUN:
            dropout[run] = True
        elif r[left] < near_m and r[right] < near_m:
            near[run] = True  # something closer than the sensor measures: not free space
    return valid, said & ~dropout & ~near, dropout


def _invalid_runs(invalid: np.ndarray, circular: bool):
    """Each run of invalid beams (indices) with the valid beam before and after it (None
    at the ends of a partial field of view; around the seam of a full circle)."""
    n = len(invalid)
    if n == 0 or invalid.all() or not invalid.any():
        return
    shift = int(np.argmin(invalid)) if circular else 0  # a circle starts on a return
    m = np.roll(invalid, -shift)
    edges = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
    for a, b in zip(np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0], strict=True):
        left = (a - 1 + shift) % n if (circular or a > 0) else None
        right = (b + shift) % n if (circular or b < n) else None
        yield (np.arange(a, b) + shift) % n, left, right


def scan_to_points(
    scan: LaserScan,
    frontier_range_m: float = 0.2,
    mount: tuple[float, float, float, bool] = (0.0, 0.0, 0.0, False),
    no_return_free_m: float | None = None,
    out_of_range: str = "inf",
    motion: np.ndarray | None = None,
) -> ScanPoints:
    """Points of a scan in the robot frame; ``mount`` = (x, y, yaw, upside_down).

    ``no_return_free_m`` (metres; default ``frontier_range_m``) is where a beam with no
    return ends. ``motion`` (beams x 3): the robot's pose when each beam was taken, in the
    robot frame the points are wanted in (``deskew_motion``)."""
    mx, my = mount[:2]
    r = np.asarray(scan.ranges, dtype=float)
    a = beam_angles(scan, mount)
    valid, no_return, dropout = classify(scan, out_of_range)
    free_m = frontier_range_m if no_return_free_m is None else no_return_free_m
    share = NO_RETURN_SHARE * scan.range_max
    rr = np.where(valid, r, np.where(no_return, min(free_m, share), min(frontier_range_m, share)))
    xy = np.stack([mx + rr * np.cos(a), my + rr * np.sin(a)], axis=1)
    keep = ~dropout
    if motion is not None:  # each point from where its beam was taken
        m = np.asarray(motion, dtype=float)
        c, s = np.cos(m[:, 2]), np.sin(m[:, 2])
        xy = np.stack(
            [m[:, 0] + c * xy[:, 0] - s * xy[:, 1], m[:, 1] + s * xy[:, 0] + c * xy[:, 1]], axis=1
        )
    origin = np.array([mx, my], dtype=float)
    # a partial field of view is ordered from the middle of what it does not see
    gap = math.atan2(np.sin(a).mean(), np.cos(a).mean()) + math.pi
    idx, full = _around_sensor(xy[keep], origin, scan, gap)
    return ScanPoints(xy[keep][idx], valid[keep][idx], full, origin, no_return[keep][idx])


def _around_sensor(
    xy: np.ndarray, origin: np.ndarray, scan: LaserScan, gap: float
) -> tuple[np.ndarray, bool]:
    """The points' indices in counter-clockwise order around the sensor (a star-shaped,
    hence simple, polygon), starting after the direction ``gap``; where a full circle
    taken while turning overlaps itself, the older beams go. And whether they close a
    full circle."""
    bearing = np.arctan2(xy[:, 1] - origin[1], xy[:, 0] - origin[0])
    idx = np.arange(len(xy))
    step = abs(scan.angle_increment)
    full = step * len(scan.ranges) >= 2 * np.pi - 1e-6
    if full and len(bearing) > 2:
        turn = np.unwrap(bearing)
        if turn[-1] < turn[0]:  # the beams ran clockwise
            turn = -turn
        if turn[-1] - turn[0] > 2 * np.pi - step / 2:  # the last beams cover the first ones
            keep = turn > turn[-1] - 2 * np.pi + step / 2
            idx, bearing, turn = idx[keep], bearing[keep], turn[keep]
        full = bool(turn[-1] - turn[0] >= 2 * np.pi - 1.5 * step)
    order = np.argsort((bearing - gap) % (2 * np.pi), kind="stable")
    return idx[order], full


def deskew_motion(scan: LaserScan, odom_at) -> np.ndarray | None:
    """The robot's pose at each beam's time in its frame at the sweep's end (beams x 3),
    from ``odom_at(times) -> (k, 3)`` odometry poses; None when the beams were taken at
    one instant (nothing to correct)."""
    if scan.time_increment <= 0 or len(scan.ranges) < 2:
        return None
    poses = np.asarray(odom_at(scan.beam_stamps), dtype=float)
    end = poses[-1]
    c, s = math.cos(end[2]), math.sin(end[2])
    d = poses[:, :2] - end[:2]
    rel = np.stack(
        [c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], poses[:, 2] - end[2]], axis=1
    )
    rel[:, 2] = (rel[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return rel


def isolated_blobs(
    points: ScanPoints, max_width_m: float, max_range_m: float = BLOB_RANGE_M
) -> np.ndarray:
    """Which of ``points`` (bool, (n,)) belong to an isolated blob: a run of returns on
    consecutive beams, each within ``BLOB_JUMP_M`` (and ``BLOB_JUMP_SHARE`` of its
    range) of the next, no wider end to end than ``max_width_m``, nearer than
    ``max_range_m``, whose neighbouring beams on both sides see at least ``BLOB_GAP_M``
    farther (or no return). Another robot in open space is one; so is a post. On a full
    circle the last point neighbours the first; a run at either end of a partial sweep
    has one neighbour only and is not one."""
    xy, ok = points.xy, points.valid
    n = len(xy)
    out = np.zeros(n, dtype=bool)
    if n < 3 or not ok.any():
        return out
    r = np.hypot(xy[:, 0] - points.origin[0], xy[:, 1] - points.origin[1])
    nxt = np.roll(np.arange(n), -1)  # each point's next; on a partial sweep the last has none
    step = np.hypot(*(xy[nxt] - xy).T)
    joined = ok & ok[nxt] & (step <= BLOB_JUMP_M + BLOB_JUMP_SHARE * np.minimum(r, r[nxt]))
    if not points.full_circle:
        joined[-1] = False
    elif joined.all():
        return out  # one run all the way round: a room, not a blob
    # runs start after a point not joined to its next; on a full circle, begin after one
    first = int(np.flatnonzero(~joined)[0]) + 1 if points.full_circle else 0
    order = np.roll(np.arange(n), -first)  # positions in sweep order, from a break
    k = 0
    while k < n:
        a = order[k]
        if not ok[a]:
            k += 1
            continue
        run = [a]
        while joined[run[-1]] and len(run) < n:
            run.append(nxt[run[-1]])
        k += len(run)
        before, after = (a - 1) % n, nxt[run[-1]]
        if not points.full_circle and (a == 0 or run[-1] == n - 1):
            continue  # a neighbour missing (the sweep's ends)
        idx = np.array(run)
        if np.hypot(*(xy[run[-1]] - xy[a])) > max_width_m or r[idx].max() > max_range_m:
            continue
        near = r[idx].min() + BLOB_GAP_M
        if (not ok[before] or r[before] >= near) and (not ok[after] or r[after] >= near):
            out[idx] = True
    return out
