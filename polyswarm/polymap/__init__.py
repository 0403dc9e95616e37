"""PolyMap: explored free space as typed, directed vectors, stored on square cells.

Conventions (see ``protocols/PROTOCOL.md``):

* frame: right-handed, x right / y up, metres;
* a *vector* is a directed segment with a type (obstacle, frontier, sector);
* explored free space lies on the LEFT of every vector, so outer rings run
  counter-clockwise and inner rings (around obstacles inside a cell) clockwise;
* every vertex lies on a 10 micrometre precision grid (``PRECISION_M``); set operations
  round to that grid (GEOS snap rounding as the fallback), never exact float tests. The
  grid is fine enough that merging keyframes in any order gives the same explored area
  but for strips thinner than ``SLIVER_M`` (property tests: the keyframes' perimeters
  x SLIVER_M at most), and coarse enough to absorb floating-point noise;
* the map is a ``GridPolyMap``: a grid of square cells, each holding the explored
  space inside its square as closed simple rings. A vector on a cell border with
  explored space on the other side is a *sector*; the cell is also the unit of a delta.

Map objects are immutable: ``merge`` returns a new map (and the changed cells), so a
failed merge can never leave a half-updated map behind.

Modules, in the order they build on each other:

* ``rings``: the precision grid, vector types, rings and typed polygons;
* ``regions``: shapely regions of cells (overlays snapped to the grid, clipping);
* ``cells``: a cell of the grid, holding the explored space inside its square;
* ``partition``: a cell's convex pieces (for navigation and point location);
* ``borders``: which cell-border vectors are sectors;
* ``vectortypes``: typing merged vectors (obstacle, frontier, sector; noise rules);
* ``deltas``: deltas, merge operations and their digests;
* ``merge``: merging polygons and cells into a map (``GridPolyMap``'s merges);
* ``queries``: questions to a map (free space, pieces, vectors, area);
* ``gridmap``: ``GridPolyMap`` itself: cells, versions, deltas and replay.
"""

from polyswarm.polymap.cells import Cell
from polyswarm.polymap.deltas import (
    MapDelta,
    MergeOp,
    MergeOptions,
    MergeResult,
    cells_digest,
    snap_polygon,
)
from polyswarm.polymap.gridmap import GridPolyMap
from polyswarm.polymap.rings import (
    BORDER_TOL_M,
    MATCH_TOL_M,
    PRECISION_M,
    SLIVER_M,
    UNITS_PER_M,
    CellIndex,
    Ring,
    TypedPolygon,
    VectorType,
    point_segment_distance,
)
from polyswarm.polymap.vectortypes import fill_notches

__all__ = [
    "BORDER_TOL_M",
    "MATCH_TOL_M",
    "PRECISION_M",
    "SLIVER_M",
    "UNITS_PER_M",
    "Cell",
    "CellIndex",
    "GridPolyMap",
    "MapDelta",
    "MergeOp",
    "MergeOptions",
    "MergeResult",
    "Ring",
    "TypedPolygon",
    "VectorType",
    "cells_digest",
    "fill_notches",
    "point_segment_distance",
    "snap_polygon",
]
