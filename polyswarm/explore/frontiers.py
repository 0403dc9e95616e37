"""Frontier segments: frontier vectors chained across cells.

Vectors are chained where one ends and the next starts on the same point of the
precision grid (compared as integers, with one grid step of slack for rounding across cells).

    segs = extract_frontiers(map, min_length_m=0.4, max_length_m=4.0)
    segs[0].length_m, segs[0].midpoint
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass

import numpy as np

from polyswarm.polymap import UNITS_PER_M, GridPolyMap, VectorType


@dataclass(frozen=True, eq=False)
class FrontierSegment:
    points: np.ndarray  # (k, 2) polyline, free space on its left
    length_m: float
    chain: int = 0  # pieces split from one chain of frontier vectors share this number

    @functools.cached_property
    def midpoint(self) -> np.ndarray:
        """The point halfway along the polyline."""
        return point_along(self.points, 0.5 * self.length_m)

    @property
    def start(self) -> np.ndarray:
        return self.points[0]

    @property
    def end(self) -> np.ndarray:
        return self.points[-1]


def point_along(points: np.ndarray, distance: float) -> np.ndarray:
    """The point ``distance`` (metres, clipped to the polyline) along a polyline."""
    return points_along(points, np.array([distance]))[0]


def points_along(points: np.ndarray, distances: np.ndarray) -> np.ndarray:
    """The points ``distances`` (metres, clipped to the polyline) along a polyline."""
    seg = np.diff(points, axis=0)
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))])
    d = np.clip(np.asarray(distances, dtype=float), 0.0, cum[-1])
    return np.stack([np.interp(d, cum, points[:, 0]), np.interp(d, cum, points[:, 1])], axis=1)


def _point_keys(q: np.ndarray) -> np.ndarray:
    """One int64 per integer grid point (x in the high, y in the low 32 bits)."""
    return (q[:, 0] << 32) + (q[:, 1] + (1 << 31))


def chain_vectors(starts: np.ndarray, ends: np.ndarray) -> list[np.ndarray]:
    """Chain directed vectors end-to-start into polylines (index lists).

    A vector's successor is the first unused vector (in index order) that starts on its
    end point, else within one grid step of it (offsets tried in a fixed order)."""
    n = len(starts)
    if n == 0:
        return []
    qs = np.rint(starts * UNITS_PER_M).astype(np.int64)
    qe = np.rint(ends * UNITS_PER_M).astype(np.int64)
    keys = _point_keys(qs)
    order = np.argsort(keys, kind="stable")  # equal keys stay in index order
    sorted_keys = keys[order]
    offsets = [(dx, dy) for dx in (0, -1, 1) for dy in (0, -1, 1)]
    # every vector's first candidate while none is used, for all vectors at once
    first = np.full(n, -1, dtype=np.int64)
    me = np.arange(n)
    for dx, dy in offsets:
        q = _point_keys(qe + np.array([dx, dy]))
        pos = np.searchsorted(sorted_keys, q)
        for skip in (0, 1):  # the vector itself is not its successor: the next one there
            at = np.minimum(pos + skip, n - 1)
            cand = order[at]
            take = (first < 0) & (pos + skip < n) & (sorted_keys[at] == q) & (cand != me)
            first[take] = cand[take]
    by_start: dict[tuple[int, int], list[int]] | None = None

    def successor(k: int, used: np.ndarray) -> int | None:
        nonlocal by_start
        j = int(first[k])
        if j < 0:
            return None
        if not used[j]:
            return j
        if by_start is None:  # rare: the first candidate is taken; search them all
            by_start = {}
            for i, (x, y) in enumerate(qs.tolist()):
                by_start.setdefault((x, y), []).append(i)
        x, y = qe[k]
        for dx, dy in offsets:
            for i in by_start.get((int(x + dx), int(y + dy)), ()):
                if not used[i] and i != k:
                    return i
        return None

    has_pred = np.zeros(n, dtype=bool)
    has_pred[first[first >= 0]] = True
    used = np.zeros(n, dtype=bool)
    chains = []
    # open chains first (they start where no vector ends), then closed loops
    for k in [*np.nonzero(~has_pred)[0].tolist(), *range(n)]:
        if used[k]:
            continue
        chain = [k]
        used[k] = True
        while (j := successor(chain[-1], used)) is not None:
            chain.append(j)
            used[j] = True
        chains.append(np.array(chain))
    return chains


def split_polyline(points: np.ndarray, max_length: float) -> list[np.ndarray]:
    """Cut a polyline into pieces no longer than ``max_length`` (metres)."""
    return [piece for piece, _, _ in _split(points, max_length)]


def _split(points: np.ndarray, max_length: float) -> list[tuple[np.ndarray, float, np.ndarray]]:
    """``split_polyline`` with each piece's length (metres) and midpoint."""
    seg = np.diff(points, axis=0)
    L = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.concatenate([[0.0], np.cumsum(L)])
    total = float(L.sum())
    if total <= max_length or max_length <= 0:
        half = np.clip(0.5 * total, 0.0, cum[-1])
        mid = np.array([np.interp(half, cum, points[:, 0]), np.interp(half, cum, points[:, 1])])
        return [(points, total, mid)]
    k = int(np.ceil(total / max_length))
    cuts = np.linspace(0.0, total, k + 1)
    # the cut points and the pieces' midpoints, as point_along finds them
    d = np.concatenate([cuts, 0.5 * (cuts[:-1] + cuts[1:])])
    at = np.stack([np.interp(d, cum, points[:, 0]), np.interp(d, cum, points[:, 1])], axis=1)
    out = []
    for m, (a, b) in enumerate(itertools.pairwise(cuts)):
        piece = np.vstack([at[m], points[(cum > a) & (cum < b)], at[m + 1]])
        step = np.diff(piece, axis=0)
        out.append((piece, float(np.hypot(step[:, 0], step[:, 1]).sum()), at[k + 1 + m]))
    return out


def extract_frontiers(
    polymap: GridPolyMap,
    min_length_m: float = 0.0,
    max_length_m: float = 0.0,
    cache: dict | None = None,
) -> list[FrontierSegment]:
    """Frontier vectors of the map chained into segments.

    Segments shorter than ``min_length_m`` are dropped; longer than ``max_length_m``
    (if positive) are split, so that several robots can share a long frontier.
    ``cache`` (kept by the caller between calls): the pieces of every chain split last
    time, by its points; a chain the map did not change is not split again (same result).
    """
    s, e, _ = polymap.vectors([VectorType.FRONTIER])
    out = []
    old = cache.copy() if cache is not None else {}
    if cache is not None:
        cache.clear()  # only this call's chains are kept: it does not grow
    for n, chain in enumerate(chain_vectors(s, e)):
        pts = np.vstack([s[chain], e[chain[-1]][None, :]])
        key = (pts.tobytes(), max_length_m)
        pieces = old.get(key)
        if pieces is None:
            pieces = _split(pts, max_length_m)
        if cache is not None:
            cache[key] = pieces
        for piece, length, mid in pieces:
            if length >= min_length_m and length > 0:
                seg = FrontierSegment(piece, length, n)
                seg.__dict__["midpoint"] = mid  # the cached property, known already
                out.append(seg)
    return out
