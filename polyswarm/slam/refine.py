"""Stage 6 of PolySLAM: polygon refinement by line fitting (thesis 3.5, Algorithm 3).

1. The keyframe's vectors are split into *chains*: maximal runs of one type.
2. From the start of a chain, Algorithm 3 fits a line to every prefix of the chain
   (total least squares over its points), keeps the inliers from the start (both ends
   of a vector within ``inlier_threshold_m``), refits, keeps the inliers again and
   scores the result with s = w / (e + c), w = (n / (n + a))^b (formulas 3.5-3.9). The
   best-scoring sub-chain becomes one vector; the rest of the chain is fitted the same
   way until nothing is left. All prefixes are evaluated at once with prefix sums.
3. Consecutive vectors meet where their lines intersect; below ``flat_angle_deg`` the
   intersection is unstable, so both lines' projections of the shared point are used
   (averaged when closer than ``flat_merge_distance_m``).

The result is always a valid simple polygon: if the fitted ring is not, the junctions
are rebuilt from projections only, and if that fails too the raw keyframe is kept.

    poly = refine_polygon(keyframe, cfg.slam.refine)
"""

from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass

import numpy as np
import shapely

from polyswarm.config import RefineConfig
from polyswarm.errors import InvalidPolygonError
from polyswarm.polymap import Ring, TypedPolygon

log = logging.getLogger(__name__)

MAX_PREFIX = 512  # longest sub-chain considered at once (vectors); longer walls get 2 lines
FIRST_WINDOW = 64  # prefixes tried first; grown 4x while the best line fills the window
# prefixes evaluated together: a block's distance matrices (rows x points) stay in the
# processor's cache. All 512 prefixes at once took 25.6 ms a call on maze keyframes
# (2 MB matrices), 4.4 times the time of 256 for twice the prefixes
ROW_BLOCK = 64
SCORE_TIE = 0.01  # relative score difference below which the longer sub-chain is kept
FAR_INTERSECTION_M = 0.15  # an intersection farther than this from the junction is unsafe


@dataclass(frozen=True)
class LineFit:
    n_vectors: int  # vectors of the chain the line replaces (from its start)
    point: np.ndarray  # a point on the line
    normal: np.ndarray  # unit normal
    score: float


def _prefix_sums(p: np.ndarray) -> np.ndarray:
    """Cumulative (n, Sx, Sy, Sxx, Sxy, Syy) over points 0..i, shape (len, 6)."""
    x, y = p[:, 0], p[:, 1]
    cols = np.empty((len(p), 6))
    cols[:, 0] = 1.0
    cols[:, 1:3] = p
    cols[:, 3] = x * x
    cols[:, 4] = x * y
    cols[:, 5] = y * y
    return np.cumsum(cols, axis=0, out=cols)


def _pca_lines(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Total-least-squares lines of point sets given by their sums: normals, offsets."""
    n = S[:, 0]
    mx, my = S[:, 1] / n, S[:, 2] / n
    cxx = S[:, 3] / n - mx * mx
    cxy = S[:, 4] / n - mx * my
    cyy = S[:, 5] / n - my * my
    phi = 0.5 * np.arctan2(2 * cxy, cxx - cyy)  # direction of largest spread
    normal = np.empty((len(phi), 2))
    np.negative(np.sin(phi), out=normal[:, 0])
    np.cos(phi, out=normal[:, 1])
    offset = normal[:, 0] * mx + normal[:, 1] * my
    return normal, offset


def _sq_error(S: np.ndarray, normal: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Mean squared distance of point sets (sums S) to lines (normal, offset)."""
    nx, ny = normal[:, 0], normal[:, 1]
    tot = (
        nx * nx * S[:, 3]
        + 2 * nx * ny * S[:, 4]
        + ny * ny * S[:, 5]
        - 2 * offset * (nx * S[:, 1] + ny * S[:, 2])
        + S[:, 0] * offset * offset
    )
    return np.maximum(tot / S[:, 0], 0.0)


def _first_outlier(D: np.ndarray, limit: np.ndarray, threshold: float) -> np.ndarray:
    """Per row k: the first vector j in 1..limit[k]-1 with an end farther than threshold.

    ``D[k, j]`` is the distance of point j to row k's line; vector j joins points j and
    j + 1. Rows without an outlier return ``limit[k]``.
    """
    far = threshold <= D
    out = far[:, :-1] | far[:, 1:]  # vector j is an outlier
    out[:, 0] = False  # the first vector always belongs to the chain
    out &= np.arange(out.shape[1])[None, :] < limit[:, None]
    first = out.argmax(axis=1)
    return np.where(out[np.arange(len(out)), first], first, limit)


def fit_first_line(pts: np.ndarray, cfg: RefineConfig) -> LineFit:
    """Algorithm 3 on the chain with points ``pts`` (m vectors, m + 1 points).

    Prefixes are tried in windows that grow while the best sub-chain fills more
    than half of the window: a line cannot keep inliers past a point where every
    good line already broke, so longer prefixes would not change the answer.
    """
    m = len(pts) - 1
    K = min(m, FIRST_WINDOW)
    while True:
        fit = _fit_prefixes(pts, K, cfg)
        if min(m, MAX_PREFIX) <= K or fit.n_vectors <= K // 2:
            return fit
        K = min(4 * K, m, MAX_PREFIX)


def _fit_prefixes(pts: np.ndarray, K: int, cfg: RefineConfig) -> LineFit:
    P = pts[: K + 1]
    S = _prefix_sums(P)
    # prefixes in blocks of ROW_BLOCK: a prefix depends only on its own points, and a
    # block of prefixes up to k needs the distances to points 0..k only
    blocks = [_prefix_fits(P, S, lo, min(lo + ROW_BLOCK, K), cfg) for lo in range(0, K, ROW_BLOCK)]
    f2, n2, S2, score = (np.concatenate(x) for x in zip(*blocks, strict=True))
    n_pts = f2 + 1.0  # unique points of C2
    # the highest score; scores within SCORE_TIE of it are statistically the same fit, and
    # then the longest sub-chain wins (w saturates for long chains: without this a
    # straight noisy wall is cut wherever the noise happens to dip)
    near_best = score >= (1.0 - SCORE_TIE) * score.max()
    best = int(np.argmax(np.where(near_best, n_pts, -1)))
    centroid = S2[best, 1:3] / S2[best, 0]
    return LineFit(int(f2[best]), centroid, n2[best], float(score[best]))


def _prefix_fits(P: np.ndarray, S: np.ndarray, lo: int, hi: int, cfg: RefineConfig):
    """Algorithm 3's two fits for the prefixes of lo + 1 .. hi vectors: for each, the
    vectors kept (f2), the refitted line's normal, the kept points' sums and the score."""
    k = np.arange(lo + 1, hi + 1)  # prefix of k vectors = points 0..k
    Pk = P[: hi + 1]
    n1, d1 = _pca_lines(S[k])
    D1 = np.abs(n1 @ Pk.T - d1[:, None])  # distance of every point to each L1
    f1 = _first_outlier(D1, k, cfg.inlier_threshold_m)  # C1 = vectors 0..f1-1
    n2, d2 = _pca_lines(S[f1])
    D2 = np.abs(n2 @ Pk.T - d2[:, None])
    f2 = _first_outlier(D2, f1, cfg.inlier_threshold_m)  # C2 = vectors 0..f2-1
    S2 = S[f2]
    e = _sq_error(S2, n2, d2)
    n_pts = f2 + 1.0
    w = (n_pts / (n_pts + cfg.score_a)) ** cfg.score_b
    return f2, n2, S2, w / (e + cfg.score_c)


def fit_chain(pts: np.ndarray, cfg: RefineConfig) -> list[tuple[int, int, LineFit]]:
    """Cut a chain into consecutive sub-chains, each with its best line: (i0, i1, fit)."""
    out = []
    i = 0
    m = len(pts) - 1
    while i < m:
        fit = fit_first_line(pts[i:], cfg)
        n = max(1, fit.n_vectors)
        out.append((i, i + n, fit))
        i += n
    return out


def _project(p: np.ndarray, fit: LineFit) -> np.ndarray:
    d = float(np.dot(fit.normal, p - fit.point))
    return p - d * fit.normal


def _intersect(a: LineFit, b: LineFit) -> np.ndarray | None:
    A = np.array([a.normal, b.normal])
    rhs = np.array([np.dot(a.normal, a.point), np.dot(b.normal, b.point)])
    if abs(np.linalg.det(A)) < 1e-12:
        return None
    return np.linalg.solve(A, rhs)


def _angle_between(a: LineFit, b: LineFit) -> float:
    c = abs(float(np.dot(a.normal, b.normal)))
    return math.degrees(math.acos(min(1.0, c)))  # 0..90 degrees between the lines


@dataclass(frozen=True)
class RingFit:
    """A ring cut into chains and fitted with lines: the part of the refinement that
    does not depend on how lines are joined (``join_lines``)."""

    closed: np.ndarray  # the ring's vertices, rotated to start a chain, first repeated last
    pin: np.ndarray  # pinned vertices, rotated the same way
    segs: list[tuple[int, int, int, LineFit]]  # (type, first vertex, last vertex, fit)


def fit_ring(
    xy: np.ndarray, types: np.ndarray, cfg: RefineConfig, pinned: np.ndarray | None = None
) -> RingFit:
    """Algorithm 3 on every chain of a closed ring (vector i: xy[i] -> xy[i+1]);
    ``pinned`` vertices end a chain."""
    n = len(xy)
    pin = np.zeros(n, dtype=bool) if pinned is None else np.asarray(pinned, dtype=bool)
    cut = (types != np.roll(types, 1)) | pin
    change = np.nonzero(cut)[0]
    start = int(change[0]) if len(change) else 0
    xy = np.roll(xy, -start, axis=0)
    types = np.roll(types, -start)
    pin = np.roll(pin, -start)
    cut = np.roll(cut, -start)
    bounds = [*np.nonzero(cut)[0].tolist(), n] if len(change) else [0, n]
    closed = np.vstack([xy, xy[:1]])
    segs: list[tuple[int, int, int, LineFit]] = []
    for a, b in itertools.pairwise(bounds):
        if a == b:
            continue
        for i0, i1, fit in fit_chain(closed[a : b + 1], cfg):
            segs.append((int(types[a]), a + i0, a + i1, fit))
    return RingFit(closed, pin, segs)


def join_lines(
    fitted: RingFit, cfg: RefineConfig, intersections: bool = True, tents: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and vector types of the ring the fitted lines make, joined where
    consecutive lines meet (below ``flat_angle_deg``, or without ``intersections``, at
    the projections of the shared vertex). A pinned vertex stays where it is: with
    ``tents`` the lines on both sides stop at their projections of the vertex and two
    short vectors visit it, otherwise the vertex itself joins the two lines."""
    closed, pin, segs = fitted.closed, fitted.pin, fitted.segs
    n = len(closed) - 1
    out_xy: list[np.ndarray] = []
    out_t: list[int] = []
    k = len(segs)
    starts: list[list[np.ndarray]] = [[] for _ in range(k)]
    # junction between seg i and seg i+1 (cyclic): vertex index segs[i][2] (mod n)
    for i in range(k):
        _, _, end_a, fa = segs[i]
        fb = segs[(i + 1) % k][3]
        v = closed[end_a % n]
        pts = None
        if pin[end_a % n]:
            if tents:
                pts = _dedupe([_project(v, fa), v.copy(), _project(v, fb)])
            else:
                pts = [v.copy()]
        elif intersections and _angle_between(fa, fb) >= cfg.flat_angle_deg:
            x = _intersect(fa, fb)
            if x is not None and np.hypot(*(x - v)) <= FAR_INTERSECTION_M:
                pts = [x]
        if pts is None:
            pa, pb = _project(v, fa), _project(v, fb)
            if np.hypot(*(pa - pb)) < cfg.flat_merge_distance_m:
                pts = [0.5 * (pa + pb)]
            else:
                pts = [pa, pb]
        starts[(i + 1) % k] = pts
    for i in range(k):
        t = segs[i][0]
        pts = starts[i]
        # the junction points before seg i: all but the last end the previous vector
        for p in pts:
            out_xy.append(p)
            out_t.append(t)
        for j in range(len(pts) - 1):  # connectors between junction points: earlier type
            out_t[-len(pts) + j] = segs[i - 1][0]
    return np.array(out_xy), np.array(out_t, dtype=np.uint8)


def refine_ring(
    xy: np.ndarray,
    types: np.ndarray,
    cfg: RefineConfig,
    intersections: bool = True,
    pinned: np.ndarray | None = None,
    tents: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Refined vertices and vector types of a closed ring (vector i: xy[i] -> xy[i+1]):
    ``fit_ring`` then ``join_lines``."""
    if len(xy) < 3:
        return xy, types
    return join_lines(fit_ring(xy, types, cfg, pinned), cfg, intersections, tents)


def _dedupe(pts: list[np.ndarray], tol: float = 1e-6) -> list[np.ndarray]:
    out = [pts[0]]
    for p in pts[1:]:
        if np.hypot(*(p - out[-1])) > tol:
            out.append(p)
    return out


def _valid_ring(xy: np.ndarray) -> bool:
    if len(xy) < 3 or not np.isfinite(xy).all():
        return False
    ring = shapely.LinearRing(xy)
    if not ring.is_simple:
        return False
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) > 0


def refine_polygon(
    poly: TypedPolygon, cfg: RefineConfig, rounds: int = 3
) -> tuple[TypedPolygon, str]:
    """Refine a keyframe polygon; returns (polygon, how), how in
    {"refined", "projected", "raw"} saying which repair level was needed.

    With ``cfg.max_point_error_m`` > 0 every original vertex (scan point) ends within
    that distance of the result: a vertex left farther away, such as a 3-sigma noise
    point next to a fitted wall, is pinned and the ring refined again.
    """
    xy, types = poly.shell.xy, poly.shell.types
    if len(xy) < 3:
        return poly, "raw"
    limit = cfg.max_point_error_m if cfg.max_point_error_m > 0 else math.inf
    points = shapely.points(xy)
    fits: dict[bytes, RingFit] = {}  # the lines depend on the pins only: fitted once each
    for how, inter in (("refined", True), ("projected", False)):
        pinned = np.zeros(len(xy), dtype=bool)
        best = None
        for _ in range(rounds + 1):
            key = np.packbits(pinned).tobytes()
            if key not in fits:
                fits[key] = fit_ring(xy, types, cfg, pinned)
            # a tent can cross a neighbour: then a plain vertex (the same without pins)
            for tents in (True, False) if pinned.any() else (True,):
                rx, rt = join_lines(fits[key], cfg, inter, tents)
                if _valid_ring(rx):
                    break
            else:
                break  # no valid ring with these pins: keep the last valid one
            best = (rx, rt)
            far = shapely.distance(shapely.LinearRing(rx), points) > limit
            if not far.any() or (far & pinned).all():
                break
            pinned |= far
        if best is None:
            continue
        cand = TypedPolygon(Ring(*best))
        try:
            cand.validate()
            return cand, how
        except InvalidPolygonError:
            continue
    log.debug("refinement gave an invalid polygon; keeping the raw keyframe")
    return poly, "raw"
