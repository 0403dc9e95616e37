"""Isolated blobs of returns (polyswarm.slam.scan.isolated_blobs) and ICP leaving them out.

Hand-checkable scenes: a lidar at the origin with 720 beams over 270 degrees, facing +x.
"""

from __future__ import annotations

import math

import numpy as np

from polyswarm.slam.scan import LaserScan, isolated_blobs, scan_to_points

BEAMS = 720
FOV = math.radians(270.0)


def _scan(*discs, wall_x: float = 6.0) -> LaserScan:
    """A wall at x = ``wall_x`` (and walls at y = +-3 m), with discs ((x, y, radius) in
    metres) in front of them: each beam's nearest hit."""
    a = -FOV / 2 + FOV * np.arange(BEAMS) / (BEAMS - 1)
    d = np.column_stack([np.cos(a), np.sin(a)])
    r = np.full(BEAMS, np.inf)
    with np.errstate(divide="ignore"):
        for t in (wall_x / d[:, 0], 3.0 / d[:, 1], -3.0 / d[:, 1]):
            r = np.where((t > 0) & (t < r), t, r)
    r = _with_discs(d, r, discs)
    return LaserScan(np.minimum(r, 29.0), -FOV / 2, FOV / (BEAMS - 1), 0.05, 30.0)


def _with_discs(d: np.ndarray, r: np.ndarray, discs) -> np.ndarray:
    """Ranges ``r`` of beams ``d`` (unit vectors) cut short by discs (x, y, radius)."""
    for cx, cy, rad in discs:  # ray-circle: t^2 - 2 t (d.c) + |c|^2 - rad^2 = 0
        b = d @ np.array([cx, cy])
        disc = b**2 - (cx**2 + cy**2 - rad**2)
        t = b - np.sqrt(np.maximum(disc, 0.0))
        r = np.where((disc >= 0) & (t > 0) & (t < r), t, r)
    return r


def _blob_points(scan: LaserScan, width_m: float = 0.55) -> np.ndarray:
    pts = scan_to_points(scan, 30.0)
    return pts.xy[isolated_blobs(pts, width_m)]


def test_a_robot_in_open_space_is_a_blob_and_the_walls_are_not():
    """A robot (radius 0.2 m) 1.5 m ahead, 0.6 m left: every one of its returns and none
    of the walls'."""
    got = _blob_points(_scan((1.5, 0.6, 0.2)))
    assert len(got) > 10
    assert np.all(np.abs(np.hypot(got[:, 0] - 1.5, got[:, 1] - 0.6) - 0.2) < 1e-6)
    assert len(_blob_points(_scan())) == 0  # the room alone: none


def test_wide_far_or_wall_touching_objects_are_not_blobs():
    assert len(_blob_points(_scan((1.5, 0.6, 0.5)))) == 0  # 1 m wide: wider than a robot
    assert len(_blob_points(_scan((4.5, 0.0, 0.2)))) > 0  # 4.3-4.5 m: within reach
    far = _scan((5.5, 0.0, 0.2), wall_x=12.0)
    pts = scan_to_points(far, 30.0)
    assert not isolated_blobs(pts, 0.55, max_range_m=5.0).any()  # beyond 5 m
    # against the wall (0.1 m in front of it): not in front of anything by 0.3 m
    assert len(_blob_points(_scan((5.7, 0.0, 0.2)))) == 0


def _corridor(disc) -> LaserScan:
    """A corridor along x, walls at y = +-1.5 m and no end in range, with a disc (x, y,
    radius) in it; beams without a hit read the range's end (no return)."""
    a = -FOV / 2 + FOV * np.arange(BEAMS) / (BEAMS - 1)
    d = np.column_stack([np.cos(a), np.sin(a)])
    r = np.full(BEAMS, 30.0)
    with np.errstate(divide="ignore"):
        for t in (1.5 / d[:, 1], -1.5 / d[:, 1]):
            r = np.where((t > 0) & (t < r), t, r)
    return LaserScan(_with_discs(d, r, [disc]), -FOV / 2, FOV / (BEAMS - 1), 0.05, 30.0)


def test_a_robot_ahead_in_a_corridor_drags_icp_unless_left_out():
    """The robot drives 0.5 m down a corridor whose ends are out of range; another robot
    1 m ahead drives 0.2 m the same way (seen 0.7 m ahead next). Matched, its body is the
    only thing along the corridor and drags the pose back (to 0.3 m); left out as a blob,
    the corridor is degenerate and the odometry's 0.5 m holds."""
    from polyswarm.config import SlamConfig
    from polyswarm.slam.polyslam import PolySlam

    got = {}
    for blobs_m in (0.55, 0.0):
        slam = PolySlam(SlamConfig())
        slam.process(_corridor((1.0, 0.0, 0.2)), (0.0, 0.0, 0.0), blobs_m=blobs_m)
        step = slam.process(_corridor((0.7, 0.0, 0.2)), (0.5, 0.0, 0.0), blobs_m=blobs_m)
        assert step.keyframe
        got[blobs_m] = (step.pose[0], slam.blob_returns_skipped)
    assert abs(got[0.55][0] - 0.5) < 0.02 and got[0.55][1] > 0
    assert got[0.0][0] < 0.4 and got[0.0][1] == 0  # dragged back without


def test_a_full_circle_finds_a_robot_at_every_bearing():
    """A 360-degree lidar (360 beams, as the TurtleBot3's) in a round room 6 m across: a
    robot 1.5 m away is a blob whichever bearing it stands at, the one where the sweep's
    points begin and end included."""
    a = -math.pi + 2 * math.pi * np.arange(360) / 360
    d = np.column_stack([np.cos(a), np.sin(a)])
    for bearing in np.radians(np.arange(-180, 180, 15)):
        disc = (1.5 * math.cos(bearing), 1.5 * math.sin(bearing), 0.105)
        r = _with_discs(d, np.full(360, 3.0), [disc])
        pts = scan_to_points(LaserScan(r, -math.pi, 2 * math.pi / 360, 0.05, 12.0), 12.0)
        got = pts.xy[isolated_blobs(pts, 0.36)]
        assert len(got) >= 2, f"no blob at {math.degrees(bearing):.0f} deg"
        assert np.allclose(np.hypot(got[:, 0] - disc[0], got[:, 1] - disc[1]), 0.105)
