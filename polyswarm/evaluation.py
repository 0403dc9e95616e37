"""Trajectory and map accuracy metrics (pure functions, no I/O).

ate_rmse(est, ref)                 absolute trajectory error after SE(2) alignment
rpe(est, ref, 1.0)                 relative pose error over 1 m of travel
max_errors(est, ref)               largest translation / rotation error (same frame)
map_iou(explored, truth)           intersection over union of free space
wall_distance(starts, ends, walls) mean distance of obstacle vectors to true walls
phantom_obstacles(...)             length of obstacle vectors far from every true wall
ghost_wall_share(...)              share of a map's walls far from a reference map's
time_to_coverage(curve, 0.99)      first time a coverage curve reaches a fraction (t99)
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from polyswarm.se2 import relative_many, wrap


def align_se2(est_xy: np.ndarray, ref_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R and translation t minimising |R est + t - ref| (no scale)."""
    me, mr = est_xy.mean(axis=0), ref_xy.mean(axis=0)
    H = (est_xy - me).T @ (ref_xy - mr)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, mr - R @ me


def ate_rmse(est: np.ndarray, ref: np.ndarray, align: bool = True) -> float:
    e, r = np.asarray(est)[:, :2], np.asarray(ref)[:, :2]
    if align and len(e) >= 2:
        R, t = align_se2(e, r)
        e = e @ R.T + t
    return float(np.sqrt(np.mean(np.sum((e - r) ** 2, axis=1))))


def travelled(ref: np.ndarray) -> np.ndarray:
    """Cumulative distance along a trajectory."""
    step = np.hypot(*np.diff(np.asarray(ref)[:, :2], axis=0).T)
    return np.concatenate([[0.0], np.cumsum(step)])


def rpe(est: np.ndarray, ref: np.ndarray, delta_m: float) -> dict:
    """Relative pose error over pose pairs ``delta_m`` of reference travel apart."""
    cum = travelled(ref)
    i = np.arange(len(cum))
    j = np.searchsorted(cum, cum + delta_m)
    ok = j < len(cum)
    i, j = i[ok], j[ok]
    if len(i) == 0:
        return {
            "trans_mean_m": math.nan,
            "trans_std_m": math.nan,
            "rot_mean_deg": math.nan,
            "rot_std_deg": math.nan,
            "pairs": 0,
        }
    dr = relative_many(ref[i], ref[j])
    de = relative_many(est[i], est[j])
    err = relative_many(dr, de)
    t = np.hypot(err[:, 0], err[:, 1])
    r = np.degrees(np.abs(err[:, 2]))
    return {
        "trans_mean_m": float(t.mean()),
        "trans_std_m": float(t.std()),
        "rot_mean_deg": float(r.mean()),
        "rot_std_deg": float(r.std()),
        "pairs": len(i),
    }


def max_errors(est: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """Largest translational (m) and rotational (deg) error, frames as given."""
    est, ref = np.asarray(est), np.asarray(ref)
    t = np.hypot(est[:, 0] - ref[:, 0], est[:, 1] - ref[:, 1])
    r = np.degrees(np.abs(wrap(est[:, 2] - ref[:, 2])))
    return float(t.max()), float(r.max())


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


def time_to_coverage(curve, fraction: float) -> float | None:
    """The first time (s) of ``curve`` ((time s, covered fraction) pairs in time order)
    at which the covered fraction is at least ``fraction``; None if it never is."""
    return next((t for t, c in curve if c >= fraction), None)


# --- coverage: what a complete exploration must have explored --------------------------------

# walls are mostly seen from a couple of metres indoors: the lidar's noise there sets how
# far inside the true wall a correct map's boundary may lie
TYPICAL_WALL_RANGE_M = 2.0


def coverage_tolerance(noise_sigma_m: float, noise_sigma_per_m: float, resolution_m: float = 0.0):
    """Width (m) of the band along obstacles that coverage does not count: two standard
    deviations of the lidar's range noise at ``TYPICAL_WALL_RANGE_M``, or the ground
    truth's own resolution (a map_server map's pixel) if that is coarser."""
    sigma = noise_sigma_m + noise_sigma_per_m * TYPICAL_WALL_RANGE_M
    return max(2.0 * sigma, resolution_m)


def reachable_free(
    free: shapely.Geometry, radius_m: float, starts_xy, tolerance_m: float = 0.0
) -> shapely.Geometry:
    """The free space a robot of ``radius_m`` can sweep from its start: its disc's centre
    moves through ``free`` shrunk by the radius, in the parts holding a start; the disc
    covers that grown back by the radius (the reference planner's definition). A band of
    ``tolerance_m`` along every boundary is left out: a correct map's walls lie within the
    lidar's noise of the true ones, on either side."""
    centres = shapely.buffer(free, -radius_m, quad_segs=4)
    pts = [shapely.Point(float(x), float(y)) for x, y, *_ in starts_xy]
    parts = [p for p in shapely.get_parts(centres) if any(p.distance(q) < radius_m for q in pts)]
    if not parts:
        return shapely.Polygon()
    swept = shapely.intersection(shapely.buffer(shapely.union_all(parts), radius_m), free)
    return shapely.buffer(swept, -tolerance_m, quad_segs=4) if tolerance_m > 0 else swept


def occupied_cells(scans, poses: np.ndarray, mount, resolution_m: float = 0.05) -> int:
    """How many ``resolution_m`` cells the scans' returns fall in, each scan placed at its
    pose (robot frame, lidar at ``mount`` = (x, y, yaw, upside_down)). The same walls
    seen from poses that agree fill few cells; drifting poses smear them over more: of
    two trajectories for the same scans, the one with fewer cells gives the sharper map.
    A measure for data without ground truth (a recorded bag)."""
    from polyswarm.scan import beam_angles, classify

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
