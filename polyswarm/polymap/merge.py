"""Merging explored space into a map: union per cell, growth rules, typing."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np
import shapely

from polyswarm.errors import (
    GeometryError,
    InvalidPolygonError,
    MapError,
)
from polyswarm.polymap.borders import _across_changed_borders, _neighbours, _node_borders
from polyswarm.polymap.cells import Cell
from polyswarm.polymap.deltas import MergeOptions, MergeResult
from polyswarm.polymap.regions import _clean, _clip_to_cells, _union_snapped
from polyswarm.polymap.rings import (
    _EMPTY,
    MATCH_TOL_M,
    OBSTACLE,
    PRECISION_M,
    SLIVER_M,
    CellIndex,
    TypedPolygon,
)
from polyswarm.polymap.vectortypes import (
    _along_obstacles,
    _drop_thin_growth,
    _obstacle_mask,
    _segment_tree,
    _typed_cells,
    fill_notches,
)


class Merging:
    """GridPolyMap's merges (a mixin): a keyframe polygon, several at once, or other
    maps' cells; each returns a new map and the cells that changed."""

    def merge(self, polygon: TypedPolygon, options: MergeOptions | None = None) -> MergeResult:
        """Merge a free-space polygon (a keyframe) into the map.

        Explored space only grows; new explored space over an old frontier removes it;
        where an obstacle and a frontier coincide the obstacle wins. An invalid polygon
        raises ``InvalidPolygonError`` and the map is unchanged.

        ``options`` (``MergeOptions``) add the sensor-noise aware rules PolySLAM uses;
        without them the merge is the exact union with the laws of the property tests.
        """
        return self.merge_many([polygon], options)

    def merge_many(
        self,
        polygons: Sequence[TypedPolygon],
        options: MergeOptions | None = None,
        clip: shapely.Geometry | None = None,
        checked: Sequence[shapely.Geometry] | None = None,
    ) -> MergeResult:
        """Merge several polygons in one pass: their union (snapped to the map's grid)
        with the obstacle vectors of all of them, typed as ``merge`` types one polygon.

        Overlapping polygons (consecutive keyframes) touch mostly the same cells, so one
        pass costs about what merging one of them costs. The result may differ from
        merging them one by one where ``options`` judge each merge's growth (a thin
        growth one polygon adds is judged together with the others). An invalid polygon
        raises ``InvalidPolygonError`` and the map is unchanged.

        ``clip`` (an area made of whole cells): only the polygons' space inside it is
        merged (a map rebuilt in part: cells at its edge have borders typed against
        nothing beyond it, so a caller keeps only inner cells). ``checked``: the polygons
        as shapely, validated already (``TypedPolygon.validate``)."""
        polygons = list(polygons)
        if not polygons:
            return MergeResult(self, frozenset())
        geoms = list(checked) if checked is not None else [p.validate() for p in polygons]
        segs = [p.segments() for p in polygons]
        s = np.concatenate([st[t == OBSTACLE] for st, _, t in segs])
        e = np.concatenate([en[t == OBSTACLE] for _, en, t in segs])
        try:
            if clip is not None:
                geoms, s, e = _clipped(geoms, s, e, clip)
                if not geoms:
                    return MergeResult(self, frozenset())
            geom = geoms[0] if len(geoms) == 1 else shapely.union_all(geoms, grid_size=PRECISION_M)
            return self._merge_geometry(geom, s, e, options or MergeOptions())
        except shapely.errors.GEOSException as err:  # the last net: this map is unchanged
            n = len(polygons)
            raise GeometryError(f"GEOS failed to merge {n} polygon(s): {err}") from err

    def _merge_geometry(
        self,
        geom: shapely.Geometry,
        src_starts: np.ndarray,
        src_ends: np.ndarray,
        options: MergeOptions | None = None,
    ) -> MergeResult:
        shapely.prepare(geom)
        idxs = self._candidate_cells(geom.bounds)
        ij = np.array(idxs, dtype=np.float64).reshape(-1, 2) * self.cell_size
        boxes = shapely.box(
            ij[:, 0], ij[:, 1], ij[:, 0] + self.cell_size, ij[:, 1] + self.cell_size
        )
        touch = shapely.intersects(geom, boxes)
        idxs = [ix for ix, t in zip(idxs, touch, strict=True) if t]
        boxes = boxes[touch]
        inside = shapely.contains_properly(geom, boxes)
        pieces = boxes.copy()
        if (~inside).any():
            expected = geom.area - float(shapely.area(boxes[inside]).sum())
            pieces[~inside] = _clip_to_cells(geom, boxes[~inside], expected)
        return self._merge_pieces(idxs, pieces, src_starts, src_ends, options)

    def merge_cells(
        self, cells: Iterable[Cell], options: MergeOptions | None = None
    ) -> MergeResult:
        """Merge cells of other maps on the same grid (the union of all the maps).

        Several cells may share an index (cells of several robots): their regions are
        united first. ``options`` as for ``merge`` (default: the exact union)."""
        cells = [c for c in cells if c.polygons]
        for c in cells:
            if abs(c.size - self.cell_size) > 1e-9:
                raise MapError(f"cell size {c.size} m does not match the map's {self.cell_size} m")
        try:
            return self._merge_cells(cells, options)
        except shapely.errors.GEOSException as err:  # the last net: this map is unchanged
            raise GeometryError(f"GEOS failed to merge {len(cells)} cells: {err}") from err

    def _merge_cells(self, cells: list[Cell], options: MergeOptions | None) -> MergeResult:
        cells = self._cells_that_change(cells, options or MergeOptions())
        if not cells:
            return MergeResult(self, frozenset())
        # neighbours are touched too: their border vectors may turn from frontier to sector
        idxs = sorted({c.index for c in cells} | {n for c in cells for n in _neighbours(c.index)})
        groups: dict[CellIndex, list] = {}
        for c in cells:
            groups.setdefault(c.index, []).append(c.region)
        by_index = {i: g[0] for i, g in groups.items()}
        # cells sharing an index are united in rounds, one vectorised union per round
        for k in range(1, max(len(g) for g in groups.values())):
            more = [i for i, g in groups.items() if len(g) > k]
            united = _union_snapped(
                np.array([by_index[i] for i in more], dtype=object),
                np.array([groups[i][k] for i in more], dtype=object),
            )
            by_index.update(zip(more, united, strict=True))
        pieces = np.array([by_index.get(i, _EMPTY) for i in idxs], dtype=object)
        obstacle = [c.obstacle_vectors for c in cells]
        starts = np.concatenate([o[0] for o in obstacle])
        ends = np.concatenate([o[1] for o in obstacle])
        return self._merge_pieces(idxs, pieces, starts, ends, options)

    def _cells_that_change(self, cells: list[Cell], opt: MergeOptions) -> list[Cell]:
        """The cells that can change this map. A cell whose explored space this map's cell
        already covers, with no obstacle vector along one of that cell's frontiers,
        changes nothing: the union is the old region, its vectors keep their types, and
        no border moves. (Robots re-observing mapped space send mostly such cells:
        ``examples/coordinator_stages.py`` counts them in a 10-robot run.)"""
        mine = [self.cells.get(c.index) for c in cells]
        have = np.array([m is not None for m in mine], dtype=bool)
        if not have.any():
            return cells
        k = np.nonzero(have)[0]
        covered = np.zeros(len(cells), dtype=bool)
        covered[k] = shapely.covers(
            np.array([mine[i].region for i in k], dtype=object),
            np.array([cells[i].region for i in k], dtype=object),
        )
        tol = max(
            MATCH_TOL_M, opt.obstacle_snap_m, opt.obstacle_snap_behind_m, opt.obstacle_snap_front_m
        )
        # all covered cells at once: each cell's obstacle vectors against its own
        # frontiers, either way round (a short obstacle on a long frontier, or the reverse)
        k = np.nonzero(covered)[0]
        obst = [cells[i].obstacle_vectors for i in k]
        front = [mine[i].frontier_vectors for i in k]
        o_own = np.repeat(k, [len(o[0]) for o in obst])
        f_own = np.repeat(k, [len(f[0]) for f in front])
        if len(o_own) and len(f_own):
            os, oe = (np.concatenate([o[n] for o in obst]) for n in (0, 1))
            fs, fe = (np.concatenate([f[n] for f in front]) for n in (0, 1))
            on = _along_obstacles(os, oe, 0.5 * (os + oe), fs, fe, tol, owners=(o_own, f_own))
            under = _along_obstacles(fs, fe, 0.5 * (fs + fe), os, oe, tol, owners=(f_own, o_own))
            covered[o_own[on]] = False
            covered[f_own[under]] = False
        return [c for c, skip in zip(cells, covered, strict=True) if not skip]

    def _candidate_cells(self, bounds) -> list[CellIndex]:
        s = self.cell_size
        minx, miny, maxx, maxy = bounds
        # cells that merely touch the polygon count too (their border may become a sector)
        i0, j0 = math.ceil(minx / s) - 1, math.ceil(miny / s) - 1
        i1, j1 = math.floor(maxx / s), math.floor(maxy / s)
        if (i1 - i0 + 1) * (j1 - j0 + 1) > 4_000_000:
            raise InvalidPolygonError("polygon spans more than 4 million cells")
        return [(i, j) for i in range(i0, i1 + 1) for j in range(j0, j1 + 1)]

    def _merge_pieces(
        self,
        idxs: list[CellIndex],
        pieces: np.ndarray,
        src_starts: np.ndarray,
        src_ends: np.ndarray,
        options: MergeOptions | None = None,
    ) -> MergeResult:
        """Union ``pieces[k]`` into cell ``idxs[k]`` and type the resulting vectors."""
        opt = options or MergeOptions()
        # saturated cells (whole square explored, all borders sectors) cannot change
        live = [k for k, i in enumerate(idxs) if not (i in self.cells and self.cells[i].saturated)]
        if len(live) < len(idxs):
            idxs = [idxs[k] for k in live]
            pieces = pieces[live]
        if not idxs:
            return MergeResult(self, frozenset())
        old, regions = self._grown_regions(idxs, pieces, opt)
        need, starts, ends = self._to_type_again(idxs, old, regions, src_starts, src_ends, opt)
        keep = [k for k, i in enumerate(idxs) if i in need]
        idxs, regions = [idxs[k] for k in keep], regions[keep]
        regions = _node_borders(idxs, regions, self.cells, self.cell_size, need)
        neighbour_region = {i: r for i, r in zip(idxs, regions, strict=True)}
        new_cells = _typed_cells(
            idxs,
            regions,
            self.cell_size,
            starts,
            ends,
            neighbour_region,
            self.cells,
            opt.obstacle_snap_m,
            (opt.obstacle_snap_behind_m, opt.obstacle_snap_front_m),
        )
        return self._commit(idxs, new_cells, opt)

    def _grown_regions(self, idxs, pieces, opt: MergeOptions):
        """Each cell's old region and its region after the union with its piece (slivers
        and, along walls, growth thinner than ``min_growth_m`` left out)."""
        empty = shapely.Polygon()
        old = np.array(
            [self.cells[i].region if i in self.cells else empty for i in idxs], dtype=object
        )
        # a piece the old region covers leaves it as it was (most cells of a keyframe:
        # the robot sees again what it has mapped), so only the others are united
        regions = old.copy()
        grows = shapely.is_empty(old) | ~shapely.covers(old, pieces)
        if grows.any():
            regions[grows] = _clean(_union_snapped(old[grows], pieces[grows]))
        old_area = shapely.area(old)
        grew = shapely.area(regions) - old_area
        maybe = (grew > 0) & (grew <= shapely.length(old) * SLIVER_M) & ~shapely.is_empty(old)
        if maybe.any():
            k = np.nonzero(maybe)[0]
            extra = shapely.difference(regions[k], old[k])  # not rounded: keep the slivers
            thin = shapely.is_empty(shapely.buffer(extra, -SLIVER_M / 2, quad_segs=4))
            regions[k[thin]] = old[k[thin]]
        regions[(grew <= 0) & ~shapely.is_empty(old)] = old[(grew <= 0) & ~shapely.is_empty(old)]
        if opt.min_growth_m > 0:  # creep happens along walls: cells with obstacles only
            walls = np.array(
                [i in self.cells and len(self.cells[i].obstacle_vectors[0]) > 0 for i in idxs]
            )
            if walls.any():
                k = np.nonzero(walls)[0]
                walls_of = [self.cells[idxs[w]] for w in k]
                regions[k] = _drop_thin_growth(old[k], regions[k], opt.min_growth_m, walls_of)
        # nothing explored is ever lost: rounding moves a vector by less than a grid step,
        # so any larger loss is a bug, and the merge is refused as a whole
        lost = shapely.area(regions) < old_area - shapely.length(old) * PRECISION_M
        if lost.any():  # pragma: no cover - defensive
            raise MapError(
                f"merge would shrink explored space in cell {idxs[int(np.argmax(lost))]}"
            )
        return old, regions

    def _to_type_again(self, idxs, old, regions, src_starts, src_ends, opt: MergeOptions):
        """The cells whose vectors are typed again (regions that moved, neighbours across a
        changed border, cells where an obstacle vector retypes a frontier), and the
        obstacle sources (the new polygon's obstacle vectors and the cells' old ones)."""
        # a border vector must end where explored space across the border starts or ends,
        # so that only its part facing unexplored space stays a frontier
        # (only around regions that moved: the others were noded when they last changed)
        k_moved = [k for k, (r, o) in enumerate(zip(regions, old, strict=True)) if r is not o]
        moved = [idxs[k] for k in k_moved]
        # a neighbour reads a moved region only where it meets their shared border: it is
        # typed and noded again only if that changed
        need = set(moved) | _across_changed_borders(
            moved, old[k_moved], regions[k_moved], self.cell_size
        )
        # obstacle sources: the new polygon's obstacle vectors and the old ones of these cells
        olds = [self.cells[i].obstacle_vectors for i in idxs if i in self.cells]
        starts = np.concatenate([src_starts.reshape(-1, 2)] + [o[0] for o in olds])
        ends = np.concatenate([src_ends.reshape(-1, 2)] + [o[1] for o in olds])
        # a cell whose region and neighbours stay as they were can change only where an
        # obstacle vector retypes one of its frontiers; the others are not typed again
        same = [self.cells[i] for i in idxs if i not in need and i in self.cells]
        fronts = [c.frontier_vectors for c in same]
        owner = np.repeat(np.arange(len(same)), [len(f[0]) for f in fronts])
        if len(owner):
            retyped = _obstacle_mask(
                np.concatenate([f[0] for f in fronts]),
                np.concatenate([f[1] for f in fronts]),
                starts,
                ends,
                _segment_tree(starts, ends),
                opt.obstacle_snap_m,
                (opt.obstacle_snap_behind_m, opt.obstacle_snap_front_m),
            )
            need.update(same[k].index for k in np.unique(owner[retyped]))
        return need, starts, ends

    def _commit(self, idxs, new_cells, opt: MergeOptions) -> MergeResult:
        """The map with the changed cells (notches filled), one version on."""
        version = self.version + 1
        out = dict(self.cells)
        changed = set()
        for ix in idxs:
            cell = new_cells.get(ix)
            prev = self.cells.get(ix)
            if cell is None:
                # union never shrinks a region; a cell a correction emptied (kept as an
                # empty cell) stays as it is when a neighbour's merge touches it
                if prev is not None and prev.polygons:  # pragma: no cover - never seen
                    raise MapError(f"merge would remove explored space in cell {ix}")
                continue
            if cell.same_content(prev):
                continue
            if opt.notch_fill_m > 0:  # only changed cells: the others were filled before
                cell = fill_notches(cell, opt.notch_fill_m)
                if cell.same_content(prev):
                    continue
            out[ix] = cell.with_version(version)
            changed.add(ix)
        if not changed:
            return MergeResult(self, frozenset())
        return MergeResult(type(self)(self.cell_size, out, version), frozenset(changed))


def _clipped(
    geoms: list, s: np.ndarray, e: np.ndarray, area: shapely.Geometry
) -> tuple[list, np.ndarray, np.ndarray]:
    """The polygons' space inside ``area`` (intersection, not GEOS' clip_by_rect, which
    returns wrong pieces for some polygons), and the obstacle vectors near it."""
    cut = shapely.intersection(np.array(geoms, dtype=object), area, grid_size=PRECISION_M)
    parts = shapely.get_parts(cut)  # a cut can leave lines and points on the box's edge
    keep = [g for g in parts if g.geom_type == "Polygon" and g.area > 0]
    lo = np.minimum(s, e)
    hi = np.maximum(s, e)
    box = area.bounds
    m = 2.0 * SLIVER_M + 0.5  # vectors just outside still type the borders inside
    near = (
        (hi[:, 0] >= box[0] - m)
        & (lo[:, 0] <= box[2] + m)
        & (hi[:, 1] >= box[1] - m)
        & (lo[:, 1] <= box[3] + m)
    )
    return keep, s[near], e[near]
