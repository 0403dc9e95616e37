"""Map accuracy against ground truth or another map (pure functions, no I/O).

map_iou(explored, truth)           intersection over union of free space
wall_distance(starts, ends, walls) mean distance of obstacle vectors to true walls
phantom_obstacles(...)             length of obstacle vectors far from every true wall
ghost_wall_share(...)              share of a map's walls far from a reference map's
occupied_cells(scans, poses, mount) how sharp the map of a trajectory is (no ground truth)
"""

from __future__ import annotations

import math

import numpy as np
import shapely


def map_iou(explored: shapely.Geometry, truth: shapely.Geometry) -> float:
    inter = shapely.intersection(explored, truth, grid_size=1e-6).area
    union = shapely.union(explored, truth, grid_size=1e-6).area
    return float(inter / union) if union > 0 else math.nan


def wall_distance(
    starts: np.ndarray, ends: np.ndarray, wall_starts, wall_ends, step_m: float = 0.05
) -> float:
    """Mean distance (m) from points every ``step_m`` along obstacle vectors to the walls."""
    if len(starts) == 0:
        return math.nan
    dist, w = _distances_to_walls(starts, ends, wall_starts, wall_ends, step_m)
    return float(np.sum(dist * w) / np.sum(w))


def phantom_obstacles(
    starts: np.ndarray, ends: np.ndarray, wall_starts, wall_ends, far_m: float, step_m=0.05
) -> float:
    """Length (m) of obstacle vectors farther than ``far_m`` from every true wall: walls
    that are not there (another robot mapped as one, a ghost of a misaligned view)."""
    if len(starts) == 0:
        return 0.0
    dist, w = _distances_to_walls(starts, ends, wall_starts, wall_ends, step_m)
    return float(np.sum(w[dist > far_m]))


def ghost_wall_share(starts, ends, ref_starts, ref_ends, far_m: float = 0.1) -> float:
    """Share of the length of obstacle vectors ``starts -> ends`` farther than ``far_m``
    from every reference obstacle vector: walls of a map that the reference map (the
    same keyframes merged at their final, optimised poses) does not have."""
    if len(starts) == 0:
        return 0.0
    if len(ref_starts) == 0:
        return 1.0
    total = float(np.hypot(*(ends - starts).T).sum())
    return phantom_obstacles(starts, ends, ref_starts, ref_ends, far_m) / total


def _distances_to_walls(starts, ends, wall_starts, wall_ends, step_m: float):
    """Distances of points every ``step_m`` along the vectors to the nearest wall segment,
    and the length each point stands for."""
    d = ends - starts
    L = np.hypot(d[:, 0], d[:, 1])
    n = np.maximum(1, np.ceil(L / step_m).astype(int))
    owner = np.repeat(np.arange(len(starts)), n)
    first = np.cumsum(n) - n
    t = (np.arange(len(owner)) - first[owner] + 0.5) / n[owner]
    pts = starts[owner] + t[:, None] * d[owner]
    walls = shapely.STRtree(shapely.linestrings(np.stack([wall_starts, wall_ends], axis=1)))
    idx = walls.nearest(shapely.points(pts))
    dist = shapely.distance(shapely.points(pts), walls.geometries[idx])
    return dist, np.repeat(L / n, n)  # the length each point represents


def occupied_cells(scans, poses: np.ndarray, mount, resolution_m: float = 0.05) -> int:
    """How many ``resolution_m`` cells the scans' returns fall in, each scan placed at its
    pose (robot frame, lidar at ``mount`` = (x, y, yaw, upside_down)). The same walls
    seen from poses that agree fill few cells; drifting poses smear them over more: of
    two trajectories for the same scans, the one with fewer cells gives the sharper map.
    A measure for data without ground truth (a recorded bag)."""
    from polyswarm.slam.scan import beam_angles, classify

    cells = []
    for scan, (x, y, th) in zip(scans, np.asarray(poses, dtype=float), strict=True):
        valid = classify(scan)[0]
        r = np.asarray(scan.ranges, dtype=float)[valid]
        a = beam_angles(scan, mount)[valid]
        px, py = mount[0] + r * np.cos(a), mount[1] + r * np.sin(a)
        c, s = np.cos(th), np.sin(th)
        wx, wy = x + c * px - s * py, y + s * px + c * py
        cells.append(np.floor(np.stack([wx, wy], axis=1) / resolution_m).astype(np.int64))
    if not cells:
        return 0
    return len(np.unique(np.concatenate(cells), axis=0))
