"""Stage 4 of PolySLAM: point-to-vector ICP against the map's obstacle vectors.

Algorithm 2 of the thesis, as a Gauss-Newton point-to-line solver:

* backface culling: only obstacle vectors whose free (left) side faces the sensor can
  match, so a scan never locks onto the far side of a wall (thesis 3.3, 5.5);
* neighbour search: the vectors are sampled every ``sample_spacing_m`` into a cKDTree;
  each scan point takes the vector of its nearest sample (no Python loop over points);
* the outlier threshold shrinks every iteration from ``outlier_start_m`` to
  ``outlier_end_m``; the loop stops when the update is below ``tolerance_m``;
* degeneracy guard: when one translation direction is barely constrained (a corridor
  with no end in sight), the update along it is dropped, so the pose keeps the
  odometry prediction along the corridor instead of sliding.

    icp = PointToVectorIcp(cfg.slam.icp)
    res = icp.align(points_in_sensor_frame, predicted_pose, starts, ends)
    res.pose, res.inliers, res.degenerate_axis
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from polyswarm.config import IcpConfig
from polyswarm.se2 import transform_points, wrap

MIN_INLIERS = 12  # fewer matched points than this: keep the prediction
# an axis needs at least this much "points worth" of information (sum of squared normal
# components): 3, a door jamb or a corridor's end seen by a few beams. Orebro's corridors
# with 8 kept the noisy odometry along them where their doors could pin them down (40
# noise seeds: median ATE 0.143 -> 0.121 m with 3; aces 0.116 -> 0.105; 20 was 0.27 m)
MIN_CONSTRAINT = 3.0
CLAMPED_OUT = True
MAX_TANGENT_SIN = 0.5  # scan surface and map vector within 30 degrees of each other
NEIGHBOUR_GAP_M = 0.3  # scan neighbours farther apart than this give no tangent
HISTOGRAM_BINS = 360  # half-degree bins of wall directions over 180 degrees
SEARCH_STEPS_RAD = tuple(math.radians(d) for d in (1.5, 3.0, 5.0, 8.0, 12.0))  # headings tried
SEARCH_RADIUS_M = 0.15  # a point counts for a start pose when a map vector is this close
SEARCH_MARGIN = 0.02  # another heading must win by this share of the points
GOOD_START = 0.6  # no heading search when this share of points is already on the map
END_SLACK = 0.02  # metres a point may project beyond the end of its vector
# k-d tree of the samples: built for every keyframe, so built fast (sliding-midpoint
# splits, 32 points a leaf; measured on 23,000 wall samples: build 5.7 -> 3.0 ms,
# 700 queries 0.72 -> 0.47 ms); the nearest sample is exact either way
KD_LEAF = 32


@dataclass(frozen=True)
class IcpResult:
    pose: np.ndarray
    iterations: int
    inliers: int
    rmse_m: float
    converged: bool
    degenerate_axis: np.ndarray | None  # world-frame unit vector kept from the prediction
    # the fit's heading std from its last Gauss-Newton step (sigma^2 (J^T J)^-1 with sigma
    # the point-to-vector RMSE): scan noise only, so optimistic, but it grows where few
    # points or one wall direction pin the heading down (a junction seen from a corridor)
    heading_sigma_rad: float = math.inf


@dataclass(frozen=True)
class VectorIndex:
    """Obstacle vectors sampled for nearest-neighbour search."""

    starts: np.ndarray
    ends: np.ndarray
    tree: cKDTree | None
    owner: np.ndarray  # sample -> vector

    @classmethod
    def build(cls, starts: np.ndarray, ends: np.ndarray, spacing: float) -> VectorIndex:
        starts = np.asarray(starts, dtype=float).reshape(-1, 2)
        ends = np.asarray(ends, dtype=float).reshape(-1, 2)
        if len(starts) == 0:
            return cls(starts, ends, None, np.zeros(0, dtype=np.int64))
        samples, owner = sample_vectors(starts, ends, spacing)
        return cls(starts, ends, cKDTree(samples, leafsize=KD_LEAF, balanced_tree=False), owner)


def sample_vectors(starts: np.ndarray, ends: np.ndarray, spacing: float):
    """Points along every vector, both ends included, at most ``spacing`` apart; with the
    index of the vector each point lies on."""
    d = ends - starts
    L = np.hypot(d[:, 0], d[:, 1])
    n = np.maximum(1, np.ceil(L / spacing).astype(np.int64)) + 1
    owner = np.repeat(np.arange(len(starts)), n)
    first = np.cumsum(n) - n
    t = (np.arange(len(owner)) - first[owner]) / (n[owner] - 1)
    return starts[owner] + t[:, None] * d[owner], owner


def scan_tangents(points: np.ndarray) -> np.ndarray:
    """Unit surface directions at each point from its beam neighbours (0 if unknown)."""
    prev, nxt = np.roll(points, 1, axis=0), np.roll(points, -1, axis=0)
    d = nxt - prev
    ok = (np.hypot(*(points - prev).T) < NEIGHBOUR_GAP_M) & (
        np.hypot(*(nxt - points).T) < NEIGHBOUR_GAP_M
    )
    ok[[0, -1]] = False
    L = np.hypot(d[:, 0], d[:, 1])
    out = np.where((ok & (L > 0))[:, None], d / np.maximum(L, 1e-12)[:, None], 0.0)
    return out


def rotation_prealign(
    points: np.ndarray,
    pose,
    starts: np.ndarray,
    ends: np.ndarray,
    max_rad: float = math.radians(20.0),
    radius_m: float = 15.0,
) -> float:
    """Heading correction that best lines up the scan's surface directions with the
    map's wall directions (histograms of directions modulo 180 degrees, circular
    cross-correlation within +-``max_rad``). Nearest-neighbour ICP converges poorly
    from a heading error of several degrees, which odometry makes at every sharp turn;
    this brings it within reach. Returns 0 when either side has too little structure.
    """
    tan = scan_tangents(points)
    ok = np.hypot(tan[:, 0], tan[:, 1]) > 0
    if ok.sum() < MIN_INLIERS or len(starts) == 0:
        return 0.0
    a_scan = (np.arctan2(tan[ok, 1], tan[ok, 0]) + pose[2]) % math.pi
    d = ends - starts
    mid = 0.5 * (starts + ends)
    near = np.hypot(mid[:, 0] - pose[0], mid[:, 1] - pose[1]) < radius_m
    if near.sum() < 2:
        return 0.0
    a_map = np.arctan2(d[near, 1], d[near, 0]) % math.pi
    w_map = np.hypot(d[near, 0], d[near, 1])
    bins = HISTOGRAM_BINS
    h_scan = np.bincount((a_scan / math.pi * bins).astype(int) % bins, minlength=bins).astype(float)
    h_map = np.bincount((a_map / math.pi * bins).astype(int) % bins, weights=w_map, minlength=bins)
    kernel = np.exp(-0.5 * (np.arange(-3, 4) / 1.5) ** 2)
    h_scan = np.convolve(np.r_[h_scan[-3:], h_scan, h_scan[:3]], kernel, "valid")
    h_map = np.convolve(np.r_[h_map[-3:], h_map, h_map[:3]], kernel, "valid")
    reach = int(max_rad / math.pi * bins)
    shifts = np.arange(-reach, reach + 1)
    corr = np.array([np.dot(np.roll(h_scan, s), h_map) for s in shifts])
    if corr.max() <= 0:
        return 0.0
    k = int(np.argmax(corr))
    off = 0.0
    if 0 < k < len(corr) - 1:  # sub-bin peak by a parabola through three samples
        a, b, c = corr[k - 1], corr[k], corr[k + 1]
        den = a - 2 * b + c
        off = 0.5 * (a - c) / den if den < 0 else 0.0
    return float((shifts[k] + off) * math.pi / bins)


def cull_backfaces(starts: np.ndarray, ends: np.ndarray, sensor: np.ndarray) -> np.ndarray:
    """Vectors whose free (left) side faces the sensor."""
    d = ends - starts
    rel = sensor[None, :] - starts
    return d[:, 0] * rel[:, 1] - d[:, 1] * rel[:, 0] > 0


class PointToVectorIcp:
    def __init__(self, cfg: IcpConfig) -> None:
        self.cfg = cfg

    def align(
        self,
        points: np.ndarray,
        pose0,
        starts: np.ndarray,
        ends: np.ndarray,
        sensor_offset=(0.0, 0.0),
    ) -> IcpResult:
        """Align ``points`` (robot frame) to the vectors; start from ``pose0``."""
        cfg = self.cfg
        pose = np.array(pose0, dtype=float)
        starts = np.asarray(starts, dtype=float).reshape(-1, 2)
        ends = np.asarray(ends, dtype=float).reshape(-1, 2)
        if cfg.backface_culling and len(starts):
            sensor = transform_points(pose, np.asarray(sensor_offset, dtype=float)[None, :])[0]
            keep = cull_backfaces(starts, ends, sensor)
            starts, ends = starts[keep], ends[keep]
        index = VectorIndex.build(starts, ends, cfg.sample_spacing_m)
        start = pose
        if cfg.rotation_search_rad > 0 and index.tree is not None and len(points) >= MIN_INLIERS:
            start = self._best_start(points, pose, starts, ends, index)
        res = self.align_index(points, start, index)
        if not np.array_equal(start, pose):
            # the search scores headings coarsely (points within SEARCH_RADIUS_M); where it
            # moved the start, ICP from the prediction competes: a converged fit beats one
            # still oscillating, then more inliers win. (On orebro, a junction seen from a
            # new corridor drew the search 8 degrees off; that fit never converged, the
            # prediction's did, 1 degree from the reference.)
            alt = self.align_index(points, pose, index)
            if (alt.converged, alt.inliers) > (res.converged, res.inliers):
                return alt
        return res

    def _best_start(self, points, pose, starts, ends, index: VectorIndex) -> np.ndarray:
        """The start pose with the most scan points near the map among a few headings:
        the prediction, the wall-direction match, and fixed steps around them."""
        cfg = self.cfg

        def score(p) -> int:
            dist, _ = index.tree.query(
                transform_points(p, points), distance_upper_bound=SEARCH_RADIUS_M
            )
            return int(np.isfinite(dist).sum())

        best, best_score = pose, score(pose)
        if best_score >= GOOD_START * len(points):
            return pose  # most points already lie on the map: nothing to search
        cands = [s * d for d in SEARCH_STEPS_RAD if d <= cfg.rotation_search_rad for s in (1, -1)]
        hist = rotation_prealign(points, pose, starts, ends, cfg.rotation_search_rad)
        if hist != 0.0:
            cands.append(hist)
        for d in cands:
            trial = np.array([pose[0], pose[1], pose[2] + d])
            s = score(trial)
            if s > best_score + SEARCH_MARGIN * len(points):
                best, best_score = trial, s
        return best

    def align_index(self, points: np.ndarray, pose0, index: VectorIndex) -> IcpResult:
        cfg = self.cfg
        pose = np.array(pose0, dtype=float)
        if index.tree is None or len(points) < MIN_INLIERS:
            return IcpResult(pose, 0, 0, math.inf, False, None)
        tangents = scan_tangents(points)
        threshold = cfg.outlier_start_m
        axis = None
        converged = False
        n_in, rmse = 0, math.inf
        heading_sigma = math.inf
        it = 0
        while it < cfg.max_iterations:
            it += 1
            world = transform_points(pose, points)
            c_, s_ = math.cos(pose[2]), math.sin(pose[2])
            tan_w = tangents @ np.array([[c_, s_], [-s_, c_]])
            corr = self._correspond(world, tan_w, index, threshold)
            if corr is None:
                break
            p, c, nrm = corr
            n_in = len(p)
            s = pose[:2]
            r = np.einsum("ij,ij->i", nrm, p - c)  # signed point-to-line distances
            rmse = float(np.sqrt(np.mean(r * r)))
            arm = p - s
            # residual n . (p - c); rotating by dtheta about the sensor moves p by
            # dtheta * perp(p - s) with perp(v) = (-v_y, v_x)
            J = np.column_stack([nrm, -nrm[:, 0] * arm[:, 1] + nrm[:, 1] * arm[:, 0]])
            delta, axis = _solve(J, r, cfg.degeneracy_ratio)
            heading_sigma = _heading_sigma(J, rmse, axis is not None)
            pose[0] += delta[0]
            pose[1] += delta[1]
            pose[2] = float(wrap(pose[2] + delta[2]))
            small = (
                math.hypot(delta[0], delta[1]) < cfg.tolerance_m and abs(delta[2]) < cfg.tolerance_m
            )
            if small and threshold <= cfg.outlier_end_m + 1e-12:
                converged = True
                break
            threshold = max(cfg.outlier_end_m, threshold * cfg.shrink)
        return IcpResult(pose, it, n_in, rmse, converged, axis, heading_sigma)

    def _correspond(
        self, world: np.ndarray, tangents: np.ndarray, index: VectorIndex, threshold: float
    ):
        dist, k = index.tree.query(
            world, distance_upper_bound=threshold + self.cfg.sample_spacing_m
        )
        ok = np.isfinite(dist)
        if ok.sum() < MIN_INLIERS:
            return None
        p = world[ok]
        tan = tangents[ok]
        j = index.owner[k[ok]]
        s, e = index.starts[j], index.ends[j]
        d = e - s
        L2 = np.einsum("ij,ij->i", d, d)
        t_raw = np.einsum("ij,ij->i", p - s, d) / np.where(L2 > 0, L2, 1.0)
        t = np.clip(t_raw, 0.0, 1.0)
        c = s + t[:, None] * d
        gap = np.hypot(*(p - c).T)
        inl = gap < threshold
        # the surface through the point must run along the vector: a point of a wall the
        # map has not seen yet, near a corner, must not pull towards the other wall
        tl = np.hypot(tan[:, 0], tan[:, 1])
        along = np.abs(tan[:, 0] * d[:, 1] - tan[:, 1] * d[:, 0]) / np.maximum(
            tl * np.sqrt(L2), 1e-12
        )
        inl &= (tl == 0) | (along < MAX_TANGENT_SIN)
        if CLAMPED_OUT:
            # a point beyond the end of its vector may lie on a wall the map has not seen
            # yet, or round a corner: its distance to the vector's line means nothing
            inl &= (t_raw >= -END_SLACK / np.sqrt(np.maximum(L2, 1e-12))) & (
                t_raw <= 1 + END_SLACK / np.sqrt(np.maximum(L2, 1e-12))
            )
        if inl.sum() < MIN_INLIERS:
            return None
        L = np.sqrt(L2[inl])
        # unit normal pointing to the free side (left of the vector)
        nrm = np.stack([-d[inl, 1], d[inl, 0]], axis=1) / np.where(L > 0, L, 1.0)[:, None]
        return p[inl], c[inl], nrm


def _heading_sigma(J: np.ndarray, rmse: float, weak: bool) -> float:
    """Std of the heading from the normal equations, sigma^2 (J^T J)^-1 (translation
    along a ``weak`` (degenerate) axis left out: there it comes from the odometry)."""
    H = J.T @ J
    _, vec = np.linalg.eigh(H[:2, :2])
    B = np.zeros((3, 2 if weak else 3))  # the constrained directions
    B[:2, : B.shape[1] - 1] = vec[:, 1:] if weak else vec
    B[2, -1] = 1.0
    try:
        cov = np.linalg.inv(B.T @ H @ B) * max(rmse, 1e-3) ** 2
    except np.linalg.LinAlgError:
        return math.inf
    return float(math.sqrt(max(cov[-1, -1], 0.0)))


def _solve(J: np.ndarray, r: np.ndarray, ratio: float) -> tuple[np.ndarray, np.ndarray | None]:
    """Gauss-Newton step; translation directions with too little information are frozen."""
    H = J.T @ J
    g = J.T @ r
    lam, vec = np.linalg.eigh(H[:2, :2])  # ascending
    weak = lam[0] < max(ratio * lam[1], MIN_CONSTRAINT)
    if not weak:
        try:
            return -np.linalg.solve(H + 1e-9 * np.eye(3), g), None
        except np.linalg.LinAlgError:
            return np.zeros(3), None
    # solve only along the well-constrained translation axis and the rotation
    good = vec[:, 1]
    B = np.zeros((3, 2))
    B[:2, 0] = good
    B[2, 1] = 1.0
    Hr = B.T @ H @ B
    try:
        sub = -np.linalg.solve(Hr + 1e-9 * np.eye(2), B.T @ g)
    except np.linalg.LinAlgError:
        return np.zeros(3), vec[:, 0]
    return B @ sub, vec[:, 0]
