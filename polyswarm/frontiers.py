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


def chain_vectors(starts: np.ndarray, ends: np.ndarray) -> list[np.ndarray]:
    """Chain directed vectors end-to-start into polylines (index lists)."""
    n = len(starts)
    if n == 0:
        return []
    qs = np.rint(starts * UNITS_PER_M).astype(np.int64)
    qe = np.rint(ends * UNITS_PER_M).astype(np.int64)
    by_start: dict[tuple[int, int], list[int]] = {}
    for k, (x, y) in enumerate(qs.tolist()):
        by_start.setdefault((x, y), []).append(k)

    def successor(k: int, used: np.ndarray) -> int | None:
        x, y = qe[k]
        for dx in (0, -1, 1):
            for dy in (0, -1, 1):
                for j in by_start.get((int(x + dx), int(y + dy)), ()):
                    if not used[j] and j != k:
                        return j
        return None

    has_pred = np.zeros(n, dtype=bool)
    dummy = np.zeros(n, dtype=bool)
    for k in range(n):
        j = successor(k, dummy)
        if j is not None:
            has_pred[j] = True
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
    seg = np.diff(points, axis=0)
    total = float(np.hypot(seg[:, 0], seg[:, 1]).sum())
    if total <= max_length or max_length <= 0:
        return [points]
    k = int(np.ceil(total / max_length))
    cuts = np.linspace(0.0, total, k + 1)
    L = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.concatenate([[0.0], np.cumsum(L)])
    out = []
    for a, b in itertools.pairwise(cuts):
        inner = points[(cum > a) & (cum < b)]
        out.append(np.vstack([point_along(points, a), inner, point_along(points, b)]))
    return out


def extract_frontiers(
    polymap: GridPolyMap, min_length_m: float = 0.0, max_length_m: float = 0.0
) -> list[FrontierSegment]:
    """Frontier vectors of the map chained into segments.

    Segments shorter than ``min_length_m`` are dropped; longer than ``max_length_m``
    (if positive) are split, so that several robots can share a long frontier.
    """
    s, e, _ = polymap.vectors([VectorType.FRONTIER])
    out = []
    for n, chain in enumerate(chain_vectors(s, e)):
        pts = np.vstack([s[chain], e[chain[-1]][None, :]])
        for piece in split_polyline(pts, max_length_m) if max_length_m > 0 else [pts]:
            d = np.diff(piece, axis=0)
            length = float(np.hypot(d[:, 0], d[:, 1]).sum())
            if length >= min_length_m and length > 0:
                out.append(FrontierSegment(piece, length, n))
    return out
