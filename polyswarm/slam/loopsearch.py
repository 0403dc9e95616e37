"""Wide search for a loop match: correlative scan matching on a distance field.

ICP converges only from within about its first outlier threshold (0.5 m), but after a
long loop the tracked pose can be a metre off the old map (1 m after 250 keyframes on
the aces log). This tries every pose on a grid around the tracked one (translations
every ``step_m`` within ``window_m``, headings every ``step_rad`` within
``window_rad``) and scores each by how close the scan points fall to the old map's
obstacle vectors (a Gaussian of the distance, looked up in a distance transform).
The best pose is a start for ICP, which then decides whether the loop is accepted.

    pose, score, ambiguous = correlative_search(points, pose, starts, ends)
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import distance_transform_edt

from polyswarm.se2 import transform_points
from polyswarm.slam.icp import sample_vectors

RESOLUTION_M = 0.05  # distance-field cell
HIT_SIGMA_M = 0.05  # a point this far from a wall scores exp(-1/2)
MAX_POINTS = 150  # the scan is thinned to this many points for the search
AMBIGUITY_DISTANCE_M = 0.5  # another peak this far from the best...
AMBIGUITY_RATIO = 0.95  # ...scoring this share of the best makes the match ambiguous


def _distance_field(starts, ends, lo, hi) -> np.ndarray:
    shape = np.ceil((hi - lo) / RESOLUTION_M).astype(int) + 1
    pts, _ = sample_vectors(starts, ends, 0.5 * RESOLUTION_M)
    ij = np.floor((pts - lo) / RESOLUTION_M).astype(int)
    ok = (ij >= 0).all(axis=1) & (ij < shape).all(axis=1)
    free = np.ones(shape, dtype=bool)
    free[ij[ok, 0], ij[ok, 1]] = False
    return distance_transform_edt(free) * RESOLUTION_M


def correlative_search(
    points: np.ndarray,
    pose,
    starts: np.ndarray,
    ends: np.ndarray,
    window_m: float = 2.0,
    step_m: float = 0.1,
    window_rad: float = math.radians(6.0),
    step_rad: float = math.radians(1.0),
) -> tuple[np.ndarray, float, bool]:
    """(best pose, its score as a fraction of the points, whether another distinct pose
    scores nearly as well). Points are in the robot frame."""
    pose = np.asarray(pose, dtype=float)
    if len(points) == 0 or len(starts) == 0:
        return pose, 0.0, True
    if len(points) > MAX_POINTS:
        points = points[np.linspace(0, len(points) - 1, MAX_POINTS).astype(int)]
    world = transform_points(pose, points)
    lo = world.min(axis=0) - window_m - 1.0
    hi = world.max(axis=0) + window_m + 1.0
    field = _distance_field(starts, ends, lo, hi)
    offsets = np.arange(-window_m, window_m + 1e-9, step_m)
    turns = np.arange(-window_rad, window_rad + 1e-9, step_rad)
    best = (-1.0, pose, 0.0)
    scores = np.zeros((len(turns), len(offsets), len(offsets)))
    for a, dth in enumerate(turns):
        p = transform_points((pose[0], pose[1], pose[2] + dth), points)
        # every translation at once: (ox, oy, point) cell indices
        gx = np.floor((p[None, :, 0] + offsets[:, None] - lo[0]) / RESOLUTION_M).astype(int)
        gy = np.floor((p[None, :, 1] + offsets[:, None] - lo[1]) / RESOLUTION_M).astype(int)
        gx = np.clip(gx, 0, field.shape[0] - 1)
        gy = np.clip(gy, 0, field.shape[1] - 1)
        d = field[gx[:, None, :], gy[None, :, :]]
        s = np.exp(-0.5 * (d / HIT_SIGMA_M) ** 2).sum(axis=2)
        scores[a] = s
        k = np.unravel_index(int(np.argmax(s)), s.shape)
        if s[k] > best[0]:
            best = (float(s[k]), np.array([offsets[k[0]], offsets[k[1]]]), dth)
    score, shift, dth = best
    # ambiguous: a pose at least AMBIGUITY_DISTANCE_M away scores nearly as well
    ox, oy = np.meshgrid(offsets, offsets, indexing="ij")
    far = np.hypot(ox - shift[0], oy - shift[1]) >= AMBIGUITY_DISTANCE_M
    rival = scores[:, far].max() if far.any() else 0.0
    out = np.array([pose[0] + shift[0], pose[1] + shift[1], pose[2] + dth])
    return out, score / len(points), bool(rival >= AMBIGUITY_RATIO * score)
