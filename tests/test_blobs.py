"""Isolated blobs of returns (polyswarm.scan.isolated_blobs) and ICP leaving them out.

Hand-checkable scenes: a lidar at the origin with 720 beams over 270 degrees, facing +x.
"""

from __future__ import annotations

import math

import numpy as np

from polyswarm.scan import LaserScan, isolated_blobs, scan_to_points

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
    for cx, cy, rad in discs:  # ray-circle: t^2 - 2 t (d.c) + |c|^2 - rad^2 = 0
        b = d @ np.array([cx, cy])
        disc = b**2 - (cx**2 + cy**2 - rad**2)
        t = b - np.sqrt(np.maximum(disc, 0.0))
        r = np.where((disc >= 0) & (t > 0) & (t < r), t, r)
    return LaserScan(np.minimum(r, 29.0), -FOV / 2, FOV / (BEAMS - 1), 0.05, 30.0)


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


def test_icp_leaves_blobs_out_only_when_asked():
    """PolySlam with ``blobs_m``: the robot's returns are counted as left out; without,
    none is."""
    from polyswarm.config import SlamConfig
    from polyswarm.slam import PolySlam

    scans = [_scan((1.5, 0.6, 0.2)), _scan((1.6, 0.6, 0.2))]
    for blobs_m, skipped in ((0.55, True), (0.0, False)):
        slam = PolySlam(SlamConfig())
        for k, scan in enumerate(scans):
            slam.process(scan, (0.0, 0.0, 0.0) if k == 0 else (0.5, 0.0, 0.0), blobs_m=blobs_m)
        assert (slam.blob_returns_skipped > 0) == skipped
