"""Standpoints for a robot waiting for its frame: places in its own map from which it can
be seen by the robot its candidate frame puts nearby, apart from where it stood before.

A frame is committed only once the robots saw each other in ``SEEN_APART_M``-distinct
places (``polyswarm.frames.sighting``). A waiting robot is drawn towards the other robot through
its frontiers; once its own map has none left it stands still, and where the robots
never come together on their way (a flat a long-range lidar explores from the doorways
in seconds) they are seen in one or two places and never merged. Touring standpoints
around the other robot gives the sightings places of their own.

    pts = standpoints(own_map, (x, y, heading), visited, reach_m=6.0, fov_rad=fov)  # (n, 2)
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from polyswarm.frames.sighting import BODY_M, MIN_SIGHT_M, SEEN_APART_M, WALL_CLEAR_M, Room
from polyswarm.nav.navgraph import clear_of
from polyswarm.polymap import VectorType

# nearer than this a sighting's bearing says nothing (MIN_SIGHT_M), plus a margin for the
# robots' pose errors: a standpoint at least this far from the other robot
MEET_NEAR_M = MIN_SIGHT_M + 0.4
MEET_STEP_M = 0.5  # candidate standpoints on a grid this fine (metres)
# a standpoint this far from walls by default (the coordinator passes its planner's
# obstacle clearance): a goal needs room, and a robot pressed to a wall shows little of
# itself to the other's lidar (thesis base: 0.2 m radius and a margin)
MEET_WALL_M = 0.35
# the other robot's heading is a candidate frame's guess and it may turn: standpoints this
# far inside the edges of its lidar's field of view (radians; 15 degrees)
FOV_MARGIN_RAD = math.radians(15.0)
# a sighting counts only where the return the robot makes, and the space a robot's width
# behind it, lie WALL_CLEAR_M from the viewer's walls (``polyswarm.frames.sighting.seen_where``):
# the return is up to BODY_M nearer than the robot's pose, so the stretch from BODY_M
# before it to 2 BODY_M past it, along the line of sight, is checked at these points
# (in BODY_M, 0.3 m apart: a wall end between two is at most 2 cm nearer than both). In
# the rooms world 3 of 5 standpoints reached lay 0.39-0.56 m from a wall, where the other
# robot's sightings of the waiting one could not count (seed 0, c471ed9). The sector's
# arc (ARC_CLEAR_M) is met then too: at the 6 m a standpoint lies from the other robot at
# most (``agents.meeting.MEET_MAX_M``) it reaches 0.15 m either side of the line of sight
SIGHT_SPAN = (-1.0, 0.0, 1.0, 2.0)


def standpoints(
    pmap,
    other,
    visited,
    reach_m: float,
    wall_m: float = MEET_WALL_M,
    fov_rad: float = 2 * math.pi,
) -> np.ndarray:
    """Candidate standpoints (n, 2) in ``pmap``'s explored free space: between
    ``MEET_NEAR_M`` and ``reach_m`` from the other robot (``other``: x, y and optionally
    its heading), at least ``wall_m`` from the map's obstacle vectors, with a straight
    view of it that crosses none of them. With a heading and a field of view ``fov_rad``
    under a full turn, only where its lidar looks (less ``FOV_MARGIN_RAD`` either side):
    a robot that stands still sees the waiting one only there. Of those, only the ones
    where the other robot's sighting would count (``countable``) if the map has any;
    and at least ``SEEN_APART_M`` from every point of ``visited`` ((m, 2)). Nearest to
    the other robot first."""
    other = np.asarray(other, dtype=float).reshape(-1)
    xy = other[:2]
    if reach_m <= MEET_NEAR_M:
        return np.zeros((0, 2))
    n = math.ceil(reach_m / MEET_STEP_M)
    ax = np.arange(-n, n + 1) * MEET_STEP_M
    gx, gy = np.meshgrid(ax, ax, indexing="ij")
    pts = xy + np.column_stack([gx.ravel(), gy.ravel()])
    d = np.hypot(*(pts - xy).T)
    near = (d >= MEET_NEAR_M) & (d <= reach_m)
    if len(other) > 2 and fov_rad < 2 * math.pi:
        bearing = np.arctan2(pts[:, 1] - xy[1], pts[:, 0] - xy[0]) - other[2]
        off = np.abs((bearing + math.pi) % (2 * math.pi) - math.pi)
        near &= off <= fov_rad / 2 - FOV_MARGIN_RAD
    pts, d = pts[near], d[near]
    keep = Room(pmap).allows(pts)
    pts, d = pts[keep], d[keep]
    st, en, _ = pmap.vectors([VectorType.OBSTACLE])
    if len(pts) and len(st):
        clear = clear_of(pts, st, en, wall_m)
        walls = shapely.MultiLineString([[tuple(a), tuple(b)] for a, b in zip(st, en, strict=True)])
        shapely.prepare(walls)
        sight = shapely.linestrings(np.stack([pts, np.broadcast_to(xy, pts.shape)], axis=1))
        clear &= ~shapely.intersects(sight, walls)
        pts, d = pts[clear], d[clear]
        counts = countable(pts, xy, st, en)
        if counts.any():  # else the waiting robot may still see the other from there
            pts, d = pts[counts], d[counts]
    seen = np.asarray(visited, dtype=float).reshape(-1, 2)
    if len(pts) and len(seen):
        apart = np.hypot(*(pts[:, None, :] - seen[None, :, :]).transpose(2, 0, 1))
        keep = (apart >= SEEN_APART_M).all(axis=1)
        pts, d = pts[keep], d[keep]
    return pts[np.argsort(d, kind="stable")]


def countable(pts: np.ndarray, other_xy, st: np.ndarray, en: np.ndarray) -> np.ndarray:
    """Which standpoints ``pts`` (n, 2) keep the line of sight from ``other_xy``, from
    ``BODY_M`` before each to ``2 BODY_M`` past it, ``WALL_CLEAR_M`` from the walls
    (``st``, ``en``): where the other robot's sighting of the waiting one would count.
    The waiting robot's walls stand for the viewer's: at a right frame they are the same."""
    pts = np.asarray(pts, dtype=float).reshape(-1, 2)
    if not len(pts):
        return np.zeros(0, dtype=bool)
    u = pts - np.asarray(other_xy, dtype=float)[:2]
    u /= np.maximum(np.hypot(u[:, 0], u[:, 1]), 1e-9)[:, None]
    ok = np.ones(len(pts), dtype=bool)
    for k in SIGHT_SPAN:
        ok &= clear_of(pts + k * BODY_M * u, st, en, WALL_CLEAR_M)
    return ok
