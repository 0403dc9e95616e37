"""Stage 4, refined: the keyframe's returns matched against every wall the evidence holds.

ICP matches a scan against the obstacle vectors of the keyframes near the robot. A lidar
that loses most of its beams gives ICP a few dozen points and its neighbouring keyframes
few walls, so tracking drifts a fraction of a degree a keyframe. The evidence grid
(``polyswarm.slam.evidence``) holds every scan's returns; each occupied cell knows
where its returns fell on average (finer than the cell), and the cells around it say
which way the wall runs. After ICP the pose is refined against these wall points:
Gauss-Newton on the distance from each return to the line through its nearest wall
point (point to line, Huber weights), as ICP does against vectors.

    out = refine(grid, returns_robot_frame, icp_pose, radius_m=range_max)
    pose, share, share_before = out     # share: returns within ON_WALL_M of a wall
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from polyswarm.slam.evidence import EvidenceGrid

MATCH_M = 0.3  # a return farther than this from every wall point is not matched
HUBER_M = 0.05  # residuals beyond this are down-weighted
ON_WALL_M = 0.1  # a return this close to a wall line is on a wall
NORMAL_CELLS = 2  # a wall's direction from the wall points this many cells around
ITERATIONS = 15
STEP_DONE = 1e-4  # Gauss-Newton stops when a step moves the pose less (m and rad)
MIN_RETURNS = 10  # fewer returns matched than this: nothing to refine
DAMPING = 1e-3  # Levenberg damping of the normal equations


def wall_points(grid: EvidenceGrid, xy, radius_m: float):
    """The evidence's wall points within ``radius_m`` of ``xy`` (the mean of each
    occupied cell's returns) and the unit normals of the walls there; None if none."""
    i0, i1, j0, j1 = grid.window_around(xy, radius_m)
    if i1 - i0 < 3 or j1 - j0 < 3:
        return None
    occ, pts = grid.hit_centroids((i0, i1, j0, j1))
    if len(pts) < MIN_RETURNS:
        return None
    # the wall's direction at each point: the principal axis of the points around it
    w = occ.astype(np.float64)
    x = np.zeros(occ.shape)
    y = np.zeros(occ.shape)
    x[occ], y[occ] = pts[:, 0] - xy[0], pts[:, 1] - xy[1]
    size = 2 * NORMAL_CELLS + 1
    m = [
        ndimage.uniform_filter(a, size) for a in (w, w * x, w * y, w * x * x, w * x * y, w * y * y)
    ]
    n, sx, sy, sxx, sxy, syy = (a[occ] for a in m)
    n = np.maximum(n, 1e-12)
    cxx, cxy, cyy = sxx / n - (sx / n) ** 2, sxy / n - (sx / n) * (sy / n), syy / n - (sy / n) ** 2
    along = 0.5 * np.arctan2(2 * cxy, cxx - cyy)  # the direction of largest spread
    normals = np.stack([-np.sin(along), np.cos(along)], axis=1)
    return pts, normals


def _placed(pose, pts: np.ndarray) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.stack(
        [pose[0] + c * pts[:, 0] - s * pts[:, 1], pose[1] + s * pts[:, 0] + c * pts[:, 1]],
        axis=1,
    )


def _residuals(tree, walls, normals, world: np.ndarray):
    """Each return's distance to the line through its nearest wall point (nan: none)."""
    d, k = tree.query(world, distance_upper_bound=MATCH_M)
    ok = np.isfinite(d)
    k = np.where(ok, k, 0)
    r = np.einsum("ij,ij->i", world - walls[k], normals[k])
    return np.where(ok, r, np.nan), normals[k]


def _share(r: np.ndarray) -> float:
    return float(np.mean(np.abs(np.nan_to_num(r, nan=1.0)) < ON_WALL_M)) if len(r) else 0.0


def refine(
    grid: EvidenceGrid, pts: np.ndarray, pose, radius_m: float
) -> tuple[np.ndarray, float, float] | None:
    """The pose (x, y, theta) that brings the returns ``pts`` (robot frame) onto the
    evidence's walls, from ``pose``; with the share of returns on a wall there and at
    ``pose``. None when the evidence holds no walls near the robot or too few returns
    match them."""
    found = wall_points(grid, pose[:2], radius_m)
    if found is None or len(pts) < MIN_RETURNS:
        return None
    walls, normals = found
    tree = cKDTree(walls)
    p = np.array(pose, dtype=float)
    before = None
    for _ in range(ITERATIONS):
        r, nrm = _residuals(tree, walls, normals, _placed(p, pts))
        if before is None:
            before = _share(r)
        use = np.isfinite(r)
        if use.sum() < MIN_RETURNS:
            return None
        c, s = math.cos(p[2]), math.sin(p[2])
        dxt = -s * pts[:, 0] - c * pts[:, 1]  # d(world point)/d(theta)
        dyt = c * pts[:, 0] - s * pts[:, 1]
        jac = np.stack([nrm[:, 0], nrm[:, 1], nrm[:, 0] * dxt + nrm[:, 1] * dyt], axis=1)[use]
        res = r[use]
        w = np.minimum(1.0, HUBER_M / np.maximum(np.abs(res), 1e-9))
        h = (jac * w[:, None]).T @ jac + DAMPING * np.eye(3)
        step = -np.linalg.solve(h, (jac * w[:, None]).T @ res)
        p += step
        if math.hypot(step[0], step[1]) < STEP_DONE and abs(step[2]) < STEP_DONE:
            break
    r, _ = _residuals(tree, walls, normals, _placed(p, pts))
    return p, _share(r), before
