"""The map: a grid of cells, immutable; its versions and deltas."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
import shapely
from shapely.geometry import Polygon, box

from polyswarm.errors import (
    DeltaGapError,
    MapError,
    PolyswarmError,
)
from polyswarm.polymap.cells import Cell
from polyswarm.polymap.deltas import MapDelta, MergeOp, MergeResult, cells_digest
from polyswarm.polymap.merge import Merging
from polyswarm.polymap.queries import MapQueries
from polyswarm.polymap.regions import _polygon_parts
from polyswarm.polymap.rings import OBSTACLE, PRECISION_M, CellIndex, TypedPolygon, VectorType
from polyswarm.polymap.vectortypes import _typed_polygons


@dataclass(frozen=True, eq=False)
class GridPolyMap(Merging, MapQueries):
    """A PolyMap stored on a grid of square cells (thesis 4.5), immutable."""

    cell_size: float = 2.0
    cells: Mapping[CellIndex, Cell] = field(default_factory=lambda: MappingProxyType({}))
    version: int = 0

    def __post_init__(self) -> None:
        if not (self.cell_size > 0 and math.isfinite(self.cell_size)):
            raise MapError(f"cell size must be positive, got {self.cell_size}")
        if not isinstance(self.cells, MappingProxyType):
            object.__setattr__(self, "cells", MappingProxyType(dict(self.cells)))

    def __reduce__(self):  # pickled (to a replay process) as its cells, not its caches
        return (GridPolyMap, (self.cell_size, dict(self.cells), self.version))

    def cell_index(self, x: float, y: float) -> CellIndex:
        return (math.floor(x / self.cell_size), math.floor(y / self.cell_size))

    def cell_box(self, index: CellIndex) -> Polygon:
        i, j = index
        s = self.cell_size
        return box(i * s, j * s, (i + 1) * s, (j + 1) * s)

    @classmethod
    def from_polygons(
        cls, polygons: Iterable[TypedPolygon], cell_size: float, version: int = 0
    ) -> GridPolyMap:
        """A map holding the union of ``polygons``; every cell gets ``version``."""
        polygons = list(polygons)
        if not polygons:
            return cls(cell_size, {}, version)
        geoms = [p.validate() for p in polygons]
        geom = shapely.MultiPolygon(geoms) if len(geoms) > 1 else geoms[0]
        if not geom.is_valid:  # overlapping polygons: their union is the explored space
            geom = shapely.union_all(geoms, grid_size=PRECISION_M)
        segs = [p.segments() for p in polygons]
        s = np.concatenate([x[0] for x in segs])
        e = np.concatenate([x[1] for x in segs])
        obstacle = np.concatenate([x[2] for x in segs]) == OBSTACLE
        merged = cls(cell_size)._merge_geometry(geom, s[obstacle], e[obstacle]).map
        cells = {k: c.with_version(version) for k, c in merged.cells.items()}
        return cls(cell_size, cells, version)

    def dissolve(self, precision_m: float = PRECISION_M) -> list[TypedPolygon]:
        """The explored space as polygons across cell borders (border sectors vanish),
        every vertex on a grid of ``precision_m`` (GEOS snap rounding: the result stays
        valid). Coarser than the map's 10 um, a vector moved by the rounding keeps its
        obstacle type when it runs along an obstacle within 1.5 grid steps."""
        regions = [c.region for c in self.cells.values() if c.polygons]
        if not regions:
            return []
        precision_m = max(precision_m, PRECISION_M)
        union = shapely.union_all(np.array(regions, dtype=object), grid_size=precision_m)
        polys, owner = _polygon_parts(np.array([union], dtype=object))
        s, e, _ = self.vectors([VectorType.OBSTACLE])
        snap = 1.5 * precision_m if precision_m > PRECISION_M else 0.0
        return _typed_polygons(polys, owner, s, e, obstacle_snap_m=snap).get(0, [])

    def delta_since(self, version: int) -> MapDelta:
        """All cells changed after ``version`` (the whole map for version -1)."""
        cells = tuple(c for c in self.cells.values() if c.version > version)
        return MapDelta(self.cell_size, version, self.version, cells)

    def apply_delta(self, delta: MapDelta) -> GridPolyMap:
        """Replace the delta's cells. A delta based on a newer version raises DeltaGapError."""
        if abs(delta.cell_size - self.cell_size) > 1e-9:
            raise MapError(
                f"delta cell size {delta.cell_size} m does not match the map's {self.cell_size} m"
            )
        if delta.base_version > self.version:
            raise DeltaGapError(
                f"delta applies to version {delta.base_version}, map is at {self.version}"
            )
        if delta.version <= self.version:
            return self
        out = dict(self.cells)
        for c in delta.cells:
            out[c.index] = c
        return GridPolyMap(self.cell_size, out, delta.version)

    def with_cells_of(
        self, other: GridPolyMap, indices: Iterable[CellIndex]
    ) -> tuple[GridPolyMap, list[Cell]]:
        """This map with the cells ``indices`` taken from ``other`` (a part rebuilt
        afresh; a cell ``other`` lacks becomes empty), at the next version; and the cells
        whose content changed (a ``cells_digest``'s input)."""
        version = self.version + 1
        cells = dict(self.cells)
        changed = []
        for ix in sorted(indices):
            new, old = other.cells.get(ix), cells.get(ix)
            if new is None and old is None:
                continue
            if new is not None and old is not None and new.same_content(old):
                continue
            cells[ix] = (new or Cell(ix, self.cell_size, ())).with_version(version)
            changed.append(cells[ix])
        return GridPolyMap(self.cell_size, cells, version), changed

    def replay(self, op: MergeOp) -> MergeResult:
        """Apply a ``MergeOp`` by merging its polygon again (this map must be a
        bit-identical copy of the sender's at ``op.base_version``). An op already applied
        changes nothing; one that does not apply to this version, fails to merge, or gives
        other cells than the sender's (``digest``) raises ``DeltaGapError``: fetch the map."""
        if abs(op.cell_size - self.cell_size) > 1e-9:
            raise MapError(
                f"merge cell size {op.cell_size} m does not match the map's {self.cell_size} m"
            )
        if op.version <= self.version:
            return MergeResult(self, frozenset())
        if op.base_version != self.version:
            raise DeltaGapError(
                f"merge applies to version {op.base_version}, map is at {self.version}"
            )
        try:
            res = self.merge(op.polygon, op.options)
        except PolyswarmError as e:
            raise DeltaGapError(f"the sender's merge fails here: {e}") from e
        got = cells_digest(res.map.cells[i] for i in res.changed)
        if res.map.version != op.version or got != op.digest:
            raise DeltaGapError(
                f"replaying merge {op.base_version} -> {op.version} gave other cells than "
                f"the sender's (digest {got:08x}, sent {op.digest:08x})"
            )
        return res
