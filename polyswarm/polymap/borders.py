"""Cell borders: which border vectors are sectors (explored space continues across),
and the neighbours a merge must type again."""

from __future__ import annotations

import itertools
from collections.abc import Mapping

import numpy as np
import shapely

from polyswarm.polymap.cells import Cell
from polyswarm.polymap.regions import _clean, _overlay, _polygonal, _region_at
from polyswarm.polymap.rings import _EMPTY, BORDER_TOL_M, PRECISION_M, SECTOR_TOL_M, CellIndex


def _neighbours(ix: CellIndex) -> tuple[CellIndex, ...]:
    i, j = ix
    return ((i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1))


# the sides of a cell (bottom, right, top, left): the axis their line is fixed on, whether
# it is the cell's upper bound on that axis, and the neighbour across
_SIDES = ((1, 0, (0, -1)), (0, 1, (1, 0)), (1, 1, (0, 1)), (0, 0, (-1, 0)))


def _border_keys(geoms: np.ndarray, idxs: list[CellIndex], size: float) -> list[list[bytes]]:
    """Per region and side of its cell: what a neighbour across that side reads of it
    (``_node_borders``: its vertices on the side's line; ``_border_cover``: its edges
    along that line), as bytes that are equal when the two regions read the same."""
    keys = [[b""] * 4 for _ in idxs]
    if not len(geoms):
        return keys
    parts, part_of = shapely.get_parts(geoms, return_index=True)
    rings, ring_of = shapely.get_rings(parts, return_index=True)
    xy, coord_of = shapely.get_coordinates(rings, return_index=True)
    own = part_of[ring_of[coord_of]]
    ij = np.array(idxs, dtype=np.int64).reshape(-1, 2)[own]
    next_same = np.r_[coord_of[1:] == coord_of[:-1], False]  # vertex k+1 on k's ring
    for side, (ax, far, _) in enumerate(_SIDES):
        on = np.abs(xy[:, ax] - (ij[:, ax] + far) * size) <= BORDER_TOL_M
        t = xy[:, 1 - ax]
        along = np.nonzero(on & np.r_[on[1:], False] & next_same)[0]
        lo = np.minimum(t[along], t[along + 1])
        hi = np.maximum(t[along], t[along + 1])
        v = np.nonzero(on)[0]
        # vertices (kind 0) and edges (kind 1) of each region, in a canonical order
        g = np.concatenate([own[v], own[along]])
        kind = np.concatenate([np.zeros(len(v)), np.ones(len(along))])
        a = np.concatenate([t[v], lo])
        b = np.concatenate([t[v], hi])
        if not len(g):
            continue
        order = np.lexsort((b, a, kind, g))
        g, rows = g[order], np.stack([kind, a, b], axis=1)[order]
        cut = np.nonzero(np.r_[True, g[1:] != g[:-1]])[0]
        for start, end in zip(cut, [*cut[1:], len(g)], strict=True):
            keys[g[start]][side] = rows[start:end].tobytes()
    return keys


def _across_changed_borders(
    idxs: list[CellIndex], old: np.ndarray, new: np.ndarray, size: float
) -> set[CellIndex]:
    """The neighbours of cells whose region changed from ``old`` to ``new`` along the
    border they share (so their border vectors may need new nodes or types)."""
    if not idxs:
        return set()
    before = _border_keys(old, idxs, size)
    after = _border_keys(new, idxs, size)
    return {
        (ix[0] + step[0], ix[1] + step[1])
        for ix, kb, ka in zip(idxs, before, after, strict=True)
        for (_, _, step), b, a in zip(_SIDES, kb, ka, strict=True)
        if a != b
    }


def _extra_nodes(xy, cell, t_of: dict, size: float, n_targets: int) -> dict:
    """Per target (its number in ``t_of``) and side (0 bottom, 1 right, 2 top, 3 left), the
    coordinates along the side where a neighbour's vertex nodes it and the target has none.

    ``xy``: every vertex of the targets' and neighbours' regions, ``cell``: its cell."""
    own_g, own_t, cand_g, cand_t, cand_a = [], [], [], [], []
    for side, (di, dj), across in (
        (0, (0, -1), 1),
        (1, (1, 0), 0),
        (2, (0, 1), 1),
        (3, (-1, 0), 0),
    ):
        far = side in (1, 2)  # the side's line is the cell's upper bound on that axis
        line = (cell[:, across] + far) * size
        lo = cell[:, 1 - across] * size
        on = np.abs(xy[:, across] - line) <= BORDER_TOL_M
        t = xy[:, 1 - across] - lo  # along the side, from its low end
        # own vertices: this side of a target
        k = np.nonzero(on)[0]
        tid = np.array([t_of.get(ix, -1) for ix in map(tuple, cell[k].tolist())], dtype=np.int64)
        ok = tid >= 0
        own_g.append(tid[ok] * 4 + side)
        own_t.append(t[k[ok]])
        # a neighbour's vertex on its opposite side, inside it, nodes the target's side
        opp = (side + 2) % 4
        far_o = opp in (1, 2)
        on_o = np.abs(xy[:, across] - (cell[:, across] + far_o) * size) <= BORDER_TOL_M
        on_o &= (t > BORDER_TOL_M) & (t < size - BORDER_TOL_M)
        k = np.nonzero(on_o)[0]
        host = cell[k] - np.array((di, dj))  # the target across that side
        tid = np.array([t_of.get(ix, -1) for ix in map(tuple, host.tolist())], dtype=np.int64)
        ok = tid >= 0
        cand_g.append(tid[ok] * 4 + side)
        cand_t.append(t[k[ok]])
        cand_a.append(xy[k[ok], 1 - across])
    own_g, own_t = np.concatenate(own_g), np.concatenate(own_t)
    cand_g, cand_t, cand_a = (np.concatenate(x) for x in (cand_g, cand_t, cand_a))
    has_own = np.zeros(n_targets, dtype=bool)
    has_own[np.unique(own_g // 4)] = True
    keep = has_own[cand_g // 4]  # an empty region is not noded
    # vertices the region already has there need no node
    span = 4.0 * size  # keys of different sides lie farther apart than any tolerance
    own_key = np.sort(own_g * span + own_t)
    key = cand_g * span + cand_t
    pos = np.searchsorted(own_key, key)
    near = np.full(len(key), np.inf)
    if len(own_key):
        for p_ in (pos - 1, pos):
            ok = (p_ >= 0) & (p_ < len(own_key))
            near[ok] = np.minimum(near[ok], np.abs(own_key[p_[ok]] - key[ok]))
    keep &= near > BORDER_TOL_M
    cand_g, cand_a = cand_g[keep], cand_a[keep]
    extra: dict[int, list[list[float]]] = {}
    for g in np.unique(cand_g).tolist():
        along = cand_a[cand_g == g]  # the vertices' own coordinates: exactly on the grid
        extra.setdefault(g // 4, [[], [], [], []])[g % 4] = sorted(set(along.tolist()))
    return extra


def _noded_boxes(extra: dict, target: dict, size: float) -> tuple[list, list]:
    """For each target with extra nodes: its index in the regions and its cell square
    with those nodes as vertices."""
    ks, boxes = [], []
    tlist = list(target)
    for n, sides in sorted(extra.items()):
        i, j = tlist[n]
        x0, y0 = i * size, j * size
        x1, y1 = x0 + size, y0 + size
        ring = [(x0, y0)] + [(x, y0) for x in sides[0]]
        ring += [(x1, y0)] + [(x1, y) for y in sides[1]]
        ring += [(x1, y1)] + [(x, y1) for x in reversed(sides[2])]
        ring += [(x0, y1)] + [(x0, y) for y in reversed(sides[3])]
        ks.append(target[(i, j)])
        boxes.append(shapely.Polygon(ring))
    return ks, boxes


def _node_borders(
    idxs: list[CellIndex],
    regions: np.ndarray,
    old_cells: Mapping[CellIndex, Cell],
    size: float,
    need: set[CellIndex],
) -> np.ndarray:
    """Each region with a vertex wherever a neighbour's boundary meets their shared border.

    A cell's border vector spans between its own vertices; explored space across it may
    cover only part of it (a notch of the neighbour). Intersecting the region with its
    cell square carrying those extra vertices nodes the region's border edges there
    (the overlay keeps every vertex of both inputs on shared edges; all are on the grid,
    so the geometry does not change). Only the cells in ``need`` are noded."""
    new = dict(zip(idxs, regions, strict=True))
    target = {ix: k for k, ix in enumerate(idxs) if ix in need}
    if not target:
        return regions
    # every vertex of the targets' regions and of their neighbours', with its cell
    keys = list(dict.fromkeys([*target, *(n for ix in target for n in _neighbours(ix))]))
    geoms = [_region_at(ix, new, old_cells) for ix in keys]
    xy, which = shapely.get_coordinates(
        np.array([_EMPTY if g is None else g for g in geoms], dtype=object), return_index=True
    )
    cell = np.array(keys, dtype=np.int64).reshape(-1, 2)[which]
    # per side of a target (0 bottom, 1 right, 2 top, 3 left), what lies on that line:
    # the target's own vertices, and its neighbour's inside the side (node candidates)
    t_of = {ix: n for n, ix in enumerate(target)}
    extra = _extra_nodes(xy, cell, t_of, size, len(target))
    ks, boxes = _noded_boxes(extra, target, size)
    if not ks:
        return regions
    out = regions.copy()
    noded, failed = _overlay(shapely.intersection, regions[ks], np.array(boxes, dtype=object))
    noded = _clean(_polygonal(noded))
    # where GEOS failed, or the overlay moved anything, the region stays as it was
    same = np.abs(shapely.area(noded) - shapely.area(regions[ks])) <= PRECISION_M**2 * 10
    ok = ~failed & same & shapely.is_valid(noded)
    out[np.array(ks)[ok]] = noded[ok]
    return out


def _border_cover(
    geoms: list[shapely.Geometry | None], axis: np.ndarray, at: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where each region ``geoms[k]`` reaches the line coordinate[axis[k]] == at[k] (a
    border of its cell): disjoint intervals of the other coordinate, each grown by
    SECTOR_TOL_M, as (lo, hi, k) sorted by k. A region clipped to its cell meets its
    border along edges lying on it (a vertex alone gives a point)."""
    g = np.array([_EMPTY if x is None else x for x in geoms], dtype=object)
    parts, part_of = shapely.get_parts(g, return_index=True)
    rings, ring_of = shapely.get_rings(parts, return_index=True)
    xy, coord_of = shapely.get_coordinates(rings, return_index=True)
    own = part_of[ring_of[coord_of]]
    same = coord_of[1:] == coord_of[:-1]
    p, q, own = xy[:-1][same], xy[1:][same], own[:-1][same]
    ax, line = axis[own], at[own]
    rows = np.arange(len(p))
    start = np.abs(p[rows, ax] - line) <= SECTOR_TOL_M  # every vertex there starts an edge
    along = start & (np.abs(q[rows, ax] - line) <= SECTOR_TOL_M)
    u = p[rows, 1 - ax]
    v = np.where(along, q[rows, 1 - ax], u)
    u, v, own = u[start], v[start], own[start]
    lo, hi = np.minimum(u, v) - SECTOR_TOL_M, np.maximum(u, v) + SECTOR_TOL_M
    order = np.lexsort((lo, own))
    lo, hi, own = lo[order], hi[order], own[order]
    if len(lo) == 0:
        return lo, hi, own
    # merge overlapping intervals of one region: a new one starts past the farthest end
    # so far of that region
    reach = np.empty_like(hi)
    groups = np.r_[True, own[1:] != own[:-1]]
    for s, e in itertools.pairwise([*np.nonzero(groups)[0], len(hi)]):
        reach[s:e] = np.maximum.accumulate(hi[s:e])
    first = groups | np.r_[True, lo[1:] > reach[:-1]]
    at_first = np.nonzero(first)[0]
    return lo[first], np.maximum.reduceat(hi, at_first), own[first]
