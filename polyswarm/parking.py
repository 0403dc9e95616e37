"""Where an idle robot waits without blocking a passage.

While robots whose frames are not found yet hold the end of an exploration
(``agents.anchoring``), the merged swarm's robots may have nothing left to do and stop
where they are. One that stops in a doorway shuts the waiting robot out of a room: in
the rooms world (unknown starts, seed 3, 099cc11) r2 was merged and stopped 0.4 m from a
door's centre line, and for the rest of the run every path of the waiting r3 through
that door failed ("no path with 0.300 m clearance"), its standpoints included: it was
never merged. A robot waits where another can pass it: at least ``park_clearance_m``
from the map's walls.

    pts = parking_spots(merged_map, robot_xy, clear_m=0.8, reach_m=4.0)  # (n, 2), nearest first
"""

from __future__ import annotations

import math

import numpy as np

from polyswarm.config import NavConfig
from polyswarm.navgraph import clear_of
from polyswarm.polymap import VectorType

PARK_STEP_M = 0.25  # candidate spots on a grid this fine (metres)
PARK_REACH_M = 4.0  # a spot at most this far from the robot, straight line (metres)


def park_clearance_m(nav: NavConfig) -> float:
    """The distance from walls at which a waiting robot leaves room beside it for another
    robot: its own radius, and the other's planning clearance on that side and the far
    side of its body (thesis base: 0.2 + 2 x 0.3 = 0.8 m)."""
    return nav.robot_radius_m + 2.0 * nav.obstacle_clearance_m


def blocks_passage(pmap, xy, clear_m: float) -> bool:
    """Whether a robot at ``xy`` stands closer than ``clear_m`` to a wall of ``pmap``."""
    st, en, _ = pmap.vectors(
        [VectorType.OBSTACLE], pmap.cells_within(float(xy[0]), float(xy[1]), clear_m + 1.0)
    )
    return bool(len(st)) and not clear_of(np.asarray(xy, float)[None, :2], st, en, clear_m)[0]


def parking_spots(pmap, xy, clear_m: float, reach_m: float = PARK_REACH_M) -> np.ndarray:
    """Points (n, 2) of ``pmap``'s explored free space within ``reach_m`` of ``xy`` and at
    least ``clear_m`` from its obstacle vectors; nearest first."""
    xy = np.asarray(xy, dtype=float).reshape(-1)[:2]
    n = math.ceil(reach_m / PARK_STEP_M)
    ax = np.arange(-n, n + 1) * PARK_STEP_M
    gx, gy = np.meshgrid(ax, ax, indexing="ij")
    pts = xy + np.column_stack([gx.ravel(), gy.ravel()])
    d = np.hypot(*(pts - xy).T)
    keep = d <= reach_m
    pts, d = pts[keep], d[keep]
    keep = pmap.is_free_many(pts)
    pts, d = pts[keep], d[keep]
    st, en, _ = pmap.vectors(
        [VectorType.OBSTACLE], pmap.cells_within(xy[0], xy[1], reach_m + clear_m)
    )
    if len(pts) and len(st):
        keep = clear_of(pts, st, en, clear_m)
        pts, d = pts[keep], d[keep]
    return pts[np.argsort(d, kind="stable")]
