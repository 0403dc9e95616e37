"""Shapely regions of cells: overlays snapped to the precision grid, cleaning,
clipping to cells."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
import shapely

from polyswarm.polymap.rings import _EMPTY, MIN_AREA_M2, PRECISION_M, CellIndex

if TYPE_CHECKING:  # for annotations only: no import at run time (no cycle)
    from polyswarm.polymap.cells import Cell


def _overlay(op, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``op(a, b)`` elementwise; where GEOS raises, an empty result and a failure flag."""
    try:
        return op(a, b), np.zeros(len(a), dtype=bool)
    except shapely.errors.GEOSException:
        out = np.empty(len(a), dtype=object)
        failed = np.zeros(len(a), dtype=bool)
        for k in range(len(a)):
            try:
                out[k] = op(a[k], b[k])
            except shapely.errors.GEOSException:
                out[k], failed[k] = shapely.Polygon(), True
        return out, failed


def _polygonal(geoms: np.ndarray) -> np.ndarray:
    """Keep only the polygonal part of each geometry (clipping can add lines and points)."""
    tid = shapely.get_type_id(geoms)
    out = geoms.copy()
    for k in np.nonzero(~np.isin(tid, (3, 6)))[0]:
        parts = [p for p in shapely.get_parts(geoms[k]) if shapely.get_type_id(p) in (3, 6)]
        out[k] = shapely.union_all(parts) if parts else shapely.Polygon()
    return out


def _clean(regions: np.ndarray) -> np.ndarray:
    """Each region reduced to its polygons above the sliver area (valid, oriented)."""
    parts, owner = _polygon_parts(regions)
    return _group(parts, owner, len(regions))


def _group(parts: np.ndarray, owner: np.ndarray, n: int) -> np.ndarray:
    """Polygon ``parts`` gathered into one geometry per owner (empty where none)."""
    out = np.full(n, _EMPTY, dtype=object)
    if len(parts):
        keys, counts = np.unique(owner, return_counts=True)
        parts = parts[np.argsort(owner, kind="stable")]
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        for k, s, c in zip(keys, starts, counts, strict=True):
            out[k] = parts[s] if c == 1 else shapely.MultiPolygon(list(parts[s : s + c]))
    return out


def _polygon_parts(regions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Polygon parts of each geometry (lines and points from touching inputs dropped)."""
    parts, owner = shapely.get_parts(regions, return_index=True)
    if len(parts) == 0:
        return parts, owner
    tid = shapely.get_type_id(parts)
    multi = tid == 6  # a GeometryCollection member may itself be a MultiPolygon
    if multi.any():
        sub, sub_owner = shapely.get_parts(parts[multi], return_index=True)
        parts = np.concatenate([parts[~multi], sub])
        owner = np.concatenate([owner[~multi], owner[multi][sub_owner]])
        tid = shapely.get_type_id(parts)
    keep = (tid == 3) & (shapely.area(parts) > MIN_AREA_M2)
    return shapely.orient_polygons(parts[keep], exterior_cw=False), owner[keep]


def _clip(geom, bounds) -> shapely.Geometry:
    """``geom`` clipped to a rectangle. GEOS's fast clip raises on a ring that collapses
    to 3 points (a scan corner exactly on a cell border); the exact intersection does
    not."""
    try:
        return shapely.clip_by_rect(geom, *bounds)
    except shapely.errors.GEOSException:
        return shapely.intersection(geom, shapely.box(*bounds), grid_size=PRECISION_M)


def _union_snapped(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pairwise union of valid on-grid geometries, with the result on the grid.

    A floating-point overlay keeps every input vertex (already on the grid); its new
    intersection points are rounded to the nearest grid point, which moves a vector by
    at most 0.71 grid steps. The rare outputs made invalid by rounding go through GEOS
    snap rounding (``grid_size``) instead.
    """
    union, failed = _overlay(shapely.union, a, b)
    out = shapely.set_precision(_clean(union), PRECISION_M, mode="pointwise")
    bad = failed | ~shapely.is_valid(out)
    if bad.any():
        out[bad] = shapely.union(a[bad], b[bad], grid_size=PRECISION_M)
    return out


def _clip_to_cells(geom: shapely.Geometry, boxes: np.ndarray, expected_area: float) -> np.ndarray:
    """``geom`` clipped to each box and snapped to the precision grid, valid and polygonal.

    GEOS' rectangle clipper is several times faster than a general intersection, but it
    can return a valid, wrong polygon when a vertex lies on a box corner (seen in the
    property tests): if the pieces do not add up to ``expected_area``, every piece is
    recomputed with the robust overlay. Outputs made invalid by snapping fall back to a
    snap-rounded overlay.
    """
    bb = shapely.bounds(boxes)
    out = np.empty(len(boxes), dtype=object)
    if shapely.get_num_coordinates(geom) > 2000 and len(boxes) > 16:
        # a large polygon (a converted grid map): clip to columns first, then to cells
        _, gy0, _, gy1 = geom.bounds
        for x0 in np.unique(bb[:, 0]):
            m = np.nonzero(bb[:, 0] == x0)[0]
            strip = shapely.clip_by_rect(geom, x0, gy0 - 1.0, bb[m[0], 2], gy1 + 1.0)
            for k in m:
                out[k] = _clip(strip, bb[k])
    else:
        for k, b in enumerate(bb):
            out[k] = _clip(geom, b)
    out = _polygonal(out)
    if abs(float(shapely.area(out).sum()) - expected_area) > 1e-9 * max(1.0, expected_area):
        out = _polygonal(shapely.intersection(geom, boxes))
    out = shapely.set_precision(out, PRECISION_M, mode="pointwise")
    bad = ~shapely.is_valid(out)
    if bad.any():
        out[bad] = _polygonal(shapely.intersection(geom, boxes[bad], grid_size=PRECISION_M))
    return out


def _region_at(
    ix: CellIndex, new: Mapping[CellIndex, shapely.Geometry], old_cells: Mapping[CellIndex, Cell]
) -> shapely.Geometry | None:
    """A cell's region during a merge: the new one if merged now, else the map's (or None)."""
    g = new.get(ix)
    if g is None:
        c = old_cells.get(ix)
        g = c.region if c is not None else None
    return g


def _build_regions(cells: list[Cell]) -> list[shapely.Geometry]:
    """Shapely regions of many cells at once (the same result as one at a time)."""
    rings = [
        (k, p, r)
        for k, c in enumerate(cells)
        for p, poly in enumerate(c.polygons)
        for r in poly.rings()
    ]
    if not rings:
        return [shapely.Polygon() for _ in cells]
    coords = np.concatenate([np.vstack([r.xy, r.xy[:1]]) for _, _, r in rings])
    ring_idx = np.repeat(np.arange(len(rings)), [len(r) + 1 for _, _, r in rings])
    lr = shapely.linearrings(coords, indices=ring_idx)
    keys = [(k, p) for k, p, _ in rings]
    poly_keys = list(dict.fromkeys(keys))
    poly_of = {kp: n for n, kp in enumerate(poly_keys)}
    polys = shapely.polygons(lr, indices=np.array([poly_of[kp] for kp in keys]))
    out: list[shapely.Geometry] = []
    n = 0
    for c in cells:
        m = len(c.polygons)
        geom = (
            polys[n]
            if m == 1
            else shapely.MultiPolygon(list(polys[n : n + m]))
            if m
            else shapely.Polygon()
        )
        n += m
        shapely.prepare(geom)
        out.append(geom)
    return out
