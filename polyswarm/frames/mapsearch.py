"""The search step of map matching (``polyswarm.frames.mapmatch``): for every heading, where map
B's frame puts B's walls on A's walls and neither map's walls in the other's clear
space, with no pose prior.

The score of a translation ``d`` (B's raster cell ``x`` lands on A's cell ``x + d``) at
one heading is what an FFT correlation of the two rasters at ``RESOLUTION_M`` gives:

    S(d) = sum_x A_score[x + d] B_walls[x] - CONFLICT_WEIGHT sum_y A_walls[y] B_clear[y - d]

with ``A_score = hit - CONFLICT_WEIGHT clear``. Over all 180 headings that is 180
correlations of rasters as large as both maps together: 5-30 s for a 40-80 m building
(``polyswarm bench merge``), while a coordinator matches every waiting robot every 5 s.
So the search runs coarse to fine:

1. *Coarse.* Every heading, on rasters ``COARSE`` times coarser (9 times fewer cells),
   with A's hit score taken at its best and A's and B's clear space only where a whole
   coarse cell is clear: a coarse translation scores at least about what the fine ones
   under it do, so the fine peaks stand out among the coarse ones. The best ``PEAKS`` of
   each heading are kept, ``PEAK_APART_M`` apart.
2. *Fine.* The ``COARSE_KEEP`` best coarse candidates over all headings are scored
   exactly, ``S(d)`` summed directly over B's wall cells and A's wall cells, at every
   fine translation within a coarse cell of theirs, and the best of each is kept.

On recorded explorations (``bench merge``'s robot maps, 3 robots, every third 5 s
moment; office, rooms and the procedural loop, cross and maze, one seed each, and the
thesis's 80 m loop; one process, the two searches one after the other on each pair,
measured side by side), ``match_maps`` gave the verdict of the one-pass fine
search in 67 of 68 pairs and the same pose in 57 of the 59 it accepted or proposed (the
three differences on the 80 m loop, whose corridors fit many poses; there, scored
against the true frames, ``map-search-thesis-loop.json``, both searches proposed only
wrong images of the truth, which sightings rule out, and once the coarse search missed
a rival the fine one found). A match took 0.6
against 3.8 s at the median on the loop, 1.0 against 7.0 s on the cross, 0.5 against
1.4 s on the maze, 1.8 against 18.9 s on the 80 m loop. ``search_fine`` is that one-pass
search, kept as the reference (``tests/test_mapsearch.py``,
``examples/map_search_side_by_side.py``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import fft

from polyswarm.se2 import wrap

RESOLUTION_M = 0.10  # search raster: a 2-degree heading step moves a point 10 m out 0.35 m
HEADING_STEP_RAD = math.radians(2.0)  # every heading is tried: no Manhattan assumption
CONFLICT_WEIGHT = 2.0  # a wall in the other's clear space costs two agreeing points
PEAKS = 6  # candidate poses refined by ICP
PEAK_APART_M = 1.0  # candidates closer than this (same heading) are one peak
PEAK_POOL = 400  # the best raster positions of a heading that peaks are picked from
COARSE = 3  # the first pass's cells are this many fine cells wide (0.3 m)
# coarse candidates (over all headings) scored at the fine resolution: the fine search's
# best 6 were among the best 60 coarse ones in every recorded pair
COARSE_KEEP = 60


def points_raster(xy: np.ndarray, shape, cell_m: float = RESOLUTION_M) -> np.ndarray:
    """How many of the points ``xy`` (metres from the raster's corner) fall in each cell."""
    return _count(np.floor(xy / cell_m).astype(int), shape)


def _count(ij: np.ndarray, shape) -> np.ndarray:
    img = np.zeros(shape)
    np.add.at(img, (ij[:, 0], ij[:, 1]), 1.0)
    return img


def _pool(img: np.ndarray, reduce) -> np.ndarray:
    """``img`` in blocks of ``COARSE`` x ``COARSE`` cells, each reduced to one (``np.max``
    or ``np.min``; cells past the edge count as 0)."""
    f = COARSE
    img = np.pad(img, ((0, -img.shape[0] % f), (0, -img.shape[1] % f)))
    return reduce(img.reshape(img.shape[0] // f, f, img.shape[1] // f, f), axis=(1, 3))


def _rotation(th: float) -> np.ndarray:
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s], [s, c]])


def search(a, b) -> list[tuple[float, np.ndarray]]:
    """The best (score, pose of B's frame in A's) peaks over every heading, at most
    ``3 PEAKS``, ``PEAK_APART_M`` and two heading steps apart, best first. ``a`` and
    ``b``: views of the maps (``walls`` points, raster corner ``lo``, ``hit`` and
    ``clear`` rasters at ``RESOLUTION_M``)."""
    res = RESOLUTION_M
    b_clear_xy = (np.argwhere(b.clear > 0) + 0.5) * res + b.lo
    b_center = b.walls.mean(axis=0)
    # B rotated about its centre: its points then fit in a square of its radius
    pts = np.concatenate([b.walls, b_clear_xy]) - b_center
    radius = float(np.hypot(pts[:, 0], pts[:, 1]).max())
    nb = int(np.ceil(2 * radius / res)) + 2
    off = np.full(2, radius + res)  # where B's centre lands in its rotated raster
    heads = np.arange(-math.pi, math.pi, HEADING_STEP_RAD)
    a_wall_ij = np.floor((a.walls - a.lo) / res).astype(int)
    coarse = _coarse(a, b, a_wall_ij, b_center, off, nb, heads)
    fine = _Fine(a, b, a_wall_ij, b_clear_xy, b_center, off, nb)
    found = []
    for _, h, d in coarse[:COARSE_KEEP]:
        score, dd = fine.best(heads[h], COARSE * d)
        t = a.lo + dd * res + off - _rotation(heads[h]) @ b_center
        found.append((score, np.array([t[0], t[1], heads[h]])))
    found.sort(key=lambda f: -f[0])
    return distinct(found, PEAKS * 3)


def search_fine(a, b) -> list[tuple[float, np.ndarray]]:
    """What ``search`` finds, in one pass: every heading, every translation at the fine
    resolution, one FFT correlation a heading (the search until 2026-11-28; the
    reference ``search`` is checked against, 3-10 times slower)."""
    b_clear_xy = (np.argwhere(b.clear > 0) + 0.5) * RESOLUTION_M + b.lo
    b_center = b.walls.mean(axis=0)
    pts = np.concatenate([b.walls, b_clear_xy]) - b_center
    radius = float(np.hypot(pts[:, 0], pts[:, 1]).max())
    nb = int(np.ceil(2 * radius / RESOLUTION_M)) + 2
    fshape = [fft.next_fast_len(n + nb, real=True) for n in a.hit.shape]
    fa = fft.rfft2(a.hit - CONFLICT_WEIGHT * a.clear, fshape)
    fap = fft.rfft2(points_raster(a.walls - a.lo, a.hit.shape), fshape)
    off = np.full(2, radius + RESOLUTION_M)
    found = []
    for th in np.arange(-math.pi, math.pi, HEADING_STEP_RAD):
        rot = _rotation(th)
        fbw = fft.rfft2(points_raster((b.walls - b_center) @ rot.T + off, (nb, nb)), fshape)
        fbc = fft.rfft2(points_raster((b_clear_xy - b_center) @ rot.T + off, (nb, nb)), fshape)
        corr = fft.irfft2(fa * np.conj(fbw) - CONFLICT_WEIGHT * fap * np.conj(fbc), fshape)
        for score, ij in peaks(corr, PEAKS, PEAK_APART_M / RESOLUTION_M):
            d = np.array(ij, dtype=float)
            d = np.where(d > np.array(fshape) / 2, d - np.array(fshape), d)
            t = a.lo + d * RESOLUTION_M + off - rot @ b_center
            found.append((score, np.array([t[0], t[1], th])))
    found.sort(key=lambda f: -f[0])
    return distinct(found, PEAKS * 3)


def _coarse(a, b, a_wall_ij, b_center, off, nb, heads) -> list:
    """(score, heading index, translation in coarse cells) of each heading's ``PEAKS``
    best coarse peaks, best first."""
    cell = COARSE * RESOLUTION_M
    a_score = _pool(a.hit, np.max) - CONFLICT_WEIGHT * _pool(a.clear, np.min)
    a_walls = _count(a_wall_ij // COARSE, a_score.shape)
    b_clear = (np.argwhere(_pool(b.clear, np.min) > 0) + 0.5) * cell + b.lo
    nbc = nb // COARSE + 2
    fshape = [fft.next_fast_len(n + nbc, real=True) for n in a_score.shape]
    fa_score, fa_walls = fft.rfft2(a_score, fshape), fft.rfft2(a_walls, fshape)
    out = []
    for h, th in enumerate(heads):
        rot = _rotation(th)
        bw = (b.walls - b_center) @ rot.T + off
        bc = (b_clear - b_center) @ rot.T + off
        fbw = fft.rfft2(
            _count(np.floor(bw / RESOLUTION_M).astype(int) // COARSE, (nbc, nbc)), fshape
        )
        fbc = fft.rfft2(np.minimum(points_raster(bc, (nbc, nbc), cell), 1.0), fshape)
        corr = fft.irfft2(
            fa_score * np.conj(fbw) - CONFLICT_WEIGHT * fa_walls * np.conj(fbc), fshape
        )
        for score, ij in peaks(corr, PEAKS, PEAK_APART_M / cell):
            d = np.array(ij)
            out.append((score, h, np.where(d > np.array(fshape) / 2, d - np.array(fshape), d)))
    out.sort(key=lambda c: -c[0])
    return out


class _Fine:
    """``S(d)`` at the fine resolution, summed over the maps' wall cells directly."""

    def __init__(self, a, b, a_wall_ij, b_clear_xy, b_center, off, nb) -> None:
        self.a_score = a.hit - CONFLICT_WEIGHT * a.clear
        self.a_walls, self.a_count = np.unique(a_wall_ij, axis=0, return_counts=True)
        self.b, self.b_clear_xy, self.b_center, self.off, self.nb = b, b_clear_xy, b_center, off, nb
        span = np.arange(-COARSE, COARSE + 1)
        self.window = np.stack(np.meshgrid(span, span, indexing="ij"), axis=-1).reshape(-1, 2)
        self._rasters: dict[float, tuple] = {}

    def _rotated(self, th: float) -> tuple:
        """B's wall cells (and their counts) and clear raster at heading ``th``."""
        if th not in self._rasters:
            rot = _rotation(th)
            bw = np.floor(((self.b.walls - self.b_center) @ rot.T + self.off) / RESOLUTION_M)
            walls, count = np.unique(bw.astype(int), axis=0, return_counts=True)
            clear = points_raster(
                (self.b_clear_xy - self.b_center) @ rot.T + self.off, (self.nb,) * 2
            )
            self._rasters[th] = (walls, count, clear)
        return self._rasters[th]

    def best(self, th: float, d0: np.ndarray) -> tuple[float, np.ndarray]:
        """The best score and fine translation within a coarse cell of ``d0``."""
        walls, count, clear = self._rotated(th)
        dd = d0 + self.window
        on_a = _gather(self.a_score, walls[None] + dd[:, None]) @ count
        in_b = _gather(clear, self.a_walls[None] - dd[:, None]) @ self.a_count
        score = on_a - CONFLICT_WEIGHT * in_b
        k = int(np.argmax(score))
        return float(score[k]), dd[k]


def _gather(img: np.ndarray, ij: np.ndarray) -> np.ndarray:
    """``img`` at cells ``ij`` (..., 2), 0 outside it."""
    ok = (ij >= 0).all(-1) & (ij[..., 0] < img.shape[0]) & (ij[..., 1] < img.shape[1])
    return np.where(ok, img[np.where(ok, ij[..., 0], 0), np.where(ok, ij[..., 1], 0)], 0.0)


def peaks(corr: np.ndarray, k: int, apart: float) -> list[tuple[float, tuple[int, int]]]:
    """The ``k`` best positive maxima of ``corr``, ``apart`` cells apart."""
    flat = corr.ravel()
    n = min(PEAK_POOL, flat.size)
    top = np.argpartition(flat, -n)[-n:]
    top = top[np.argsort(flat[top])[::-1]]
    out: list[tuple[float, tuple[int, int]]] = []
    for i in top:
        if flat[i] <= 0 or len(out) == k:
            break
        ij = np.unravel_index(i, corr.shape)
        if all(math.hypot(ij[0] - o[0], ij[1] - o[1]) >= apart for _, o in out):
            out.append((float(flat[i]), ij))
    return out


def distinct(found: list, k: int) -> list[tuple[float, np.ndarray]]:
    """The first ``k`` of ``found`` (score, pose) not close to one before them."""
    out: list[tuple[float, np.ndarray]] = []
    for score, pose in found:
        if all(not close(pose, p, PEAK_APART_M, 2 * HEADING_STEP_RAD) for _, p in out):
            out.append((score, pose))
            if len(out) == k:
                break
    return out


def close(p: np.ndarray, q: np.ndarray, d_m: float, d_rad: float) -> bool:
    return bool(np.hypot(*(p[:2] - q[:2])) < d_m and abs(wrap(p[2] - q[2])) < d_rad)
