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
"""

from __future__ import annotations

import hashlib
import itertools
import logging
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import astuple, dataclass, field
from enum import IntEnum
from functools import cached_property
from types import MappingProxyType

import numpy as np
import shapely
from shapely.geometry import Polygon, box

from polyswarm.errors import (
    DeltaGapError,
    GeometryError,
    InvalidPolygonError,
    MapError,
    PolyswarmError,
)

log = logging.getLogger(__name__)

PRECISION_M = 1e-5  # vertex grid: 10 um, also the quantum of the wire format
UNITS_PER_M = 100_000  # integer grid units per metre (1 / PRECISION_M, exact)
MATCH_TOL_M = 3 * PRECISION_M  # a vector this close to a source obstacle inherits its type
BORDER_TOL_M = 1e-6  # a vertex this close to a cell border lies on it (borders are on-grid)
SECTOR_TOL_M = 3 * PRECISION_M  # explored space this close across a border continues it
# A border vector is a sector if explored space across the border runs along all of it
# but gaps this long in total: two cells see the same wall a centimetre apart (each keyframe
# its own noise), and the few millimetres of border between the two walls are no way into
# unexplored space (no robot fits; frontiers shorter than 0.4 m are no targets). Measured:
# with exact ends, whole 2 m border vectors stayed frontiers beside explored cells and
# robots were sent to look at them again and again (3 robots on the thesis' loop stalled
# for 280 s at 55 % coverage).
SECTOR_GAP_M = 0.05
SNAP_ANGLE_DEG = 15.0  # a frontier snapped to an obstacle must run within this of it
BESIDE_STEP_M = 0.05  # a frontier beside a wall is tested at points this far apart...
BESIDE_ENDS_M = 0.02  # ... each beside an obstacle vector or this close past its ends
# Growth narrower than this everywhere is rounding noise, not new space: rounding an
# intersection point moves a vector by at most 0.71 grid steps, and merging a polygon
# again can meet such a vertex from the other side (measured: slivers up to ~1.4 steps).
# Ignoring them makes merging exactly idempotent; real growth that thin (possible only
# between inputs one or two grid steps apart) is dropped, which is the "up to the
# precision grid" of order independence.
SLIVER_M = 2 * PRECISION_M
# thin growth is creep along walls (dropped by MergeOptions.min_growth_m) when at least
# this share of its area lies within min_growth_m of the cell's walls
CREEP_SHARE = 0.5
MIN_AREA_M2 = 1e-9  # polygons smaller than this (30 um square) are rounding slivers

CellIndex = tuple[int, int]
_EMPTY = shapely.Polygon()  # shapely geometries are immutable: one empty region serves all


class VectorType(IntEnum):
    """Type of a directed vector; free space is on its left."""

    OBSTACLE = 0  # the outline of something solid
    FRONTIER = 1  # explored space ends, unexplored space begins
    SECTOR = 2  # explored space continues in an adjacent polygon (cell border or split)


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


# ---------------------------------------------------------------------------------------
# Rings and polygons
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Ring:
    """A closed ring of typed vectors: vector i runs from ``xy[i]`` to ``xy[(i+1) % n]``."""

    xy: np.ndarray  # (n, 2) float64, metres
    types: np.ndarray  # (n,) uint8, VectorType of vector i

    def __post_init__(self) -> None:
        xy = np.array(self.xy, dtype=np.float64).reshape(-1, 2)
        ty = np.array(self.types, dtype=np.uint8).reshape(-1)
        if len(ty) != len(xy):
            raise InvalidPolygonError(f"ring has {len(xy)} vertices but {len(ty)} vector types")
        object.__setattr__(self, "xy", _readonly(xy))
        object.__setattr__(self, "types", _readonly(ty))

    def __len__(self) -> int:
        return len(self.xy)

    @property
    def signed_area(self) -> float:
        x, y = self.xy[:, 0], self.xy[:, 1]
        return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))

    def segments(self) -> tuple[np.ndarray, np.ndarray]:
        """Start and end points of the ring's vectors."""
        return self.xy, np.concatenate([self.xy[1:], self.xy[:1]])

    def equals(self, other: Ring) -> bool:
        return (
            len(self) == len(other)
            and np.array_equal(self.xy, other.xy)
            and np.array_equal(self.types, other.types)
        )


@dataclass(frozen=True, eq=False)
class TypedPolygon:
    """A polygon with typed vectors: a counter-clockwise shell and clockwise holes."""

    shell: Ring
    holes: tuple[Ring, ...] = ()

    @classmethod
    def from_points(cls, xy, types) -> TypedPolygon:
        return cls(Ring(xy, types))

    def to_shapely(self) -> Polygon:
        return Polygon(self.shell.xy, [h.xy for h in self.holes])

    def rings(self) -> tuple[Ring, ...]:
        return (self.shell, *self.holes)

    def segments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All vectors as (starts, ends, types)."""
        if not self.holes:
            return (*self.shell.segments(), self.shell.types)
        parts = [r.segments() for r in self.rings()]
        return (
            np.concatenate([p[0] for p in parts]),
            np.concatenate([p[1] for p in parts]),
            np.concatenate([r.types for r in self.rings()]),
        )

    def validate(self) -> Polygon:
        """Check the polygon and return it as shapely; raise ``InvalidPolygonError``."""
        for k, ring in enumerate(self.rings()):
            name = "shell" if k == 0 else f"hole {k}"
            if len(ring) < 3:
                raise InvalidPolygonError(f"{name} has {len(ring)} vertices, need at least 3")
            if not np.all(np.isfinite(ring.xy)):
                raise InvalidPolygonError(f"{name} has NaN or infinite coordinates")
            if np.any(ring.types > VectorType.SECTOR):
                raise InvalidPolygonError(f"{name} has an unknown vector type")
            area = ring.signed_area
            if area == 0:
                raise InvalidPolygonError(f"{name} has no area")
            if not shapely.LinearRing(ring.xy).is_simple:
                raise InvalidPolygonError(f"{name} is not simple (it crosses itself)")
            if k == 0 and area <= 0:
                raise InvalidPolygonError(
                    "shell is clockwise or has no area: free space must be on the left "
                    "(counter-clockwise in an x-right/y-up frame)"
                )
            if k > 0 and area >= 0:
                raise InvalidPolygonError(f"{name} must run clockwise (free space on its left)")
        poly = self.to_shapely()
        if not poly.is_valid:
            raise InvalidPolygonError(f"polygon is invalid: {shapely.is_valid_reason(poly)}")
        return poly


# ---------------------------------------------------------------------------------------
# Cells
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Cell:
    """Explored space inside one grid cell: polygons of typed rings, plus a version.

    ``version`` is the map version at which the cell last changed; a delta since
    version v holds exactly the cells with ``version > v``.
    """

    index: CellIndex
    size: float
    polygons: tuple[TypedPolygon, ...]
    version: int = 0

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        i, j = self.index
        return (i * self.size, j * self.size, (i + 1) * self.size, (j + 1) * self.size)

    @cached_property
    def region(self) -> shapely.Geometry:
        """Explored free space of the cell as a shapely (Multi)Polygon."""
        return _build_regions([self])[0]

    @cached_property
    def saturated(self) -> bool:
        """The whole square is explored and every border is a sector: it cannot change."""
        if len(self.polygons) != 1 or self.polygons[0].holes:
            return False
        ring = self.polygons[0].shell
        return bool(
            (ring.types == VectorType.SECTOR).all()
            and abs(ring.signed_area - self.size * self.size) <= 1e-9 * self.size * self.size
        )

    @cached_property
    def obstacle_vectors(self) -> tuple[np.ndarray, np.ndarray]:
        return self.vectors_of_type(VectorType.OBSTACLE)

    @cached_property
    def vectors(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All vectors of the cell: (starts (n,2), ends (n,2), types (n,))."""
        if not self.polygons:
            z = np.zeros((0, 2))
            return z, z, np.zeros(0, np.uint8)
        parts = [p.segments() for p in self.polygons]
        if len(parts) == 1:
            return tuple(_readonly(np.array(x)) for x in parts[0])
        return tuple(_readonly(np.concatenate([p[k] for p in parts])) for k in range(3))

    def vectors_of_type(self, kind: VectorType) -> tuple[np.ndarray, np.ndarray]:
        s, e, t = self.vectors
        m = t == kind
        return s[m], e[m]

    def wall_zone(self, width_m: float) -> shapely.Geometry:
        """Everything within ``width_m`` of the cell's obstacle vectors (kept per width:
        a cell that new keyframes only creep along is asked again and again)."""
        zones = self.__dict__.setdefault("_wall_zones", {})
        if width_m not in zones:
            lines = _lines(*self.obstacle_vectors)
            zones[width_m] = shapely.buffer(lines, width_m, quad_segs=2)
        return zones[width_m]

    @cached_property
    def area(self) -> float:
        return float(self.region.area)

    @property
    def vector_count(self) -> int:
        return sum(len(r) for p in self.polygons for r in p.rings())

    @cached_property
    def partition(self):
        """Convex pieces of the cell joined by sector vectors (see ``polyswarm.partition``)."""
        from polyswarm.partition import partition_cell

        return partition_cell(self)

    def same_content(self, other: Cell | None) -> bool:
        if other is None or len(self.polygons) != len(other.polygons):
            return False
        for a, b in zip(self.polygons, other.polygons, strict=True):
            ra, rb = a.rings(), b.rings()
            if len(ra) != len(rb) or not all(x.equals(y) for x, y in zip(ra, rb, strict=True)):
                return False
        return True

    def with_version(self, version: int) -> Cell:
        c = Cell(self.index, self.size, self.polygons, version)
        if "region" in self.__dict__:
            c.__dict__["region"] = self.__dict__["region"]
        return c


@dataclass(frozen=True)
class MergeOptions:
    """Sensor-noise aware merging for SLAM (all off by default: the exact union).

    * ``min_growth_m``: new explored space thinner than this is ignored (an opening of
      the growth). With real lidar noise every keyframe pushes known walls a little
      outwards; the union of hundreds creeps into the walls (measured on the ACES log
      without it: median 3.5 cm).
    * ``obstacle_snap_m``: a frontier running along an obstacle vector within this
      distance is that obstacle. A wall seen at a grazing angle is a chord of frontier
      vectors in one keyframe and an obstacle, a centimetre off, in the next.
    * ``notch_fill_m``: shallow notches between obstacle vectors are filled
      (``fill_notches``), so walls do not collect teeth from every keyframe.
    * ``obstacle_snap_behind_m``, ``obstacle_snap_front_m``: a frontier lying, along its
      whole length, beside obstacle vectors running the same way, at most the first
      distance behind them (inside the wall they face) or the second in front of them,
      is that wall. A keyframe that saw a wall face at a grazing angle leaves a frontier
      chord a few centimetres inside or in front of the wall; another sees the face
      head-on. The union keeps a chord inside the wall (explored space never shrinks),
      ``min_growth_m`` keeps one in front of it, and robots were sent to look at them.
    """

    min_growth_m: float = 0.0
    obstacle_snap_m: float = 0.0
    notch_fill_m: float = 0.0
    obstacle_snap_behind_m: float = 0.0
    obstacle_snap_front_m: float = 0.0

    def on_grid(self) -> MergeOptions:
        """These options in whole 10 um units (``k / UNITS_PER_M``), as a wire carries them."""
        return MergeOptions(*(round(v * UNITS_PER_M) / UNITS_PER_M for v in astuple(self)))


@dataclass(frozen=True)
class MapDelta:
    """The cells that changed after ``base_version``, bringing a map to ``version``."""

    cell_size: float
    base_version: int
    version: int
    cells: tuple[Cell, ...]


@dataclass(frozen=True)
class MergeResult:
    map: GridPolyMap
    changed: frozenset[CellIndex]


@dataclass(frozen=True)
class MergeOp:
    """A map change sent as the operation that made it (a keyframe's delta).

    Merging ``polygon`` with ``options`` into the map at ``base_version`` gave
    ``version``; ``digest`` (``cells_digest``) hashes the exact geometry of the cells that
    changed. The merge is a pure function of the map and its inputs, so a bit-identical
    copy of the map that replays the operation (``GridPolyMap.replay``) gets the same
    cells, and the digest proves it. What a robot sends (the smaller of the two) is 2 to
    7 times fewer bytes than the changed cells (``polyswarm bench bandwidth``); the
    receiver pays the merge's computation instead.
    """

    cell_size: float
    base_version: int
    version: int
    polygon: TypedPolygon
    options: MergeOptions
    digest: int


def cells_digest(cells: Iterable[Cell]) -> int:
    """A 32-bit hash of the cells' exact geometry (indices, rings, types; not versions)."""
    h = hashlib.blake2b(digest_size=4)
    for c in sorted(cells, key=lambda c: c.index):
        h.update(np.array([*c.index, len(c.polygons)], dtype="<i8").tobytes())
        for p in c.polygons:
            for r in p.rings():
                h.update(np.array([len(r.xy)], dtype="<i8").tobytes())
                h.update(np.ascontiguousarray(r.xy, dtype="<f8").tobytes())
                h.update(np.asarray(r.types, dtype=np.uint8).tobytes())
    return int.from_bytes(h.digest(), "little")


def snap_polygon(polygon: TypedPolygon, quantum_units: int) -> TypedPolygon | None:
    """The polygon with every vertex on a grid of ``quantum_units`` 10 um units, as the
    float ``k / UNITS_PER_M`` of an integer ``k`` (so a receiver decoding ``k`` gets the
    same float). Vectors that shrink to nothing are dropped; None when the snapped
    polygon is no longer valid (a sliver that collapsed)."""
    rings = []
    for ring in polygon.rings():
        k = np.rint(ring.xy * (UNITS_PER_M / quantum_units)).astype(np.int64) * quantum_units
        keep = (k != np.roll(k, -1, axis=0)).any(axis=1)  # vector i has a length
        if keep.sum() < 3:
            return None
        rings.append(Ring(k[keep] / UNITS_PER_M, ring.types[keep]))
    out = TypedPolygon(rings[0], tuple(rings[1:]))
    try:
        out.validate()
    except InvalidPolygonError:
        return None
    return out


# ---------------------------------------------------------------------------------------
# The map
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class GridPolyMap:
    """A PolyMap stored on a grid of square cells (thesis 4.5), immutable."""

    cell_size: float = 2.0
    cells: Mapping[CellIndex, Cell] = field(default_factory=lambda: MappingProxyType({}))
    version: int = 0

    def __post_init__(self) -> None:
        if not (self.cell_size > 0 and math.isfinite(self.cell_size)):
            raise MapError(f"cell size must be positive, got {self.cell_size}")
        if not isinstance(self.cells, MappingProxyType):
            object.__setattr__(self, "cells", MappingProxyType(dict(self.cells)))

    # -- construction -------------------------------------------------------------------

    def cell_index(self, x: float, y: float) -> CellIndex:
        return (math.floor(x / self.cell_size), math.floor(y / self.cell_size))

    def cell_box(self, index: CellIndex) -> Polygon:
        i, j = index
        s = self.cell_size
        return box(i * s, j * s, (i + 1) * s, (j + 1) * s)

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
        self, polygons: Sequence[TypedPolygon], options: MergeOptions | None = None
    ) -> MergeResult:
        """Merge several polygons in one pass: their union (snapped to the map's grid)
        with the obstacle vectors of all of them, typed as ``merge`` types one polygon.

        Overlapping polygons (consecutive keyframes) touch mostly the same cells, so one
        pass costs about what merging one of them costs. The result may differ from
        merging them one by one where ``options`` judge each merge's growth (a thin
        growth one polygon adds is judged together with the others). An invalid polygon
        raises ``InvalidPolygonError`` and the map is unchanged."""
        polygons = list(polygons)
        if not polygons:
            return MergeResult(self, frozenset())
        geoms = [p.validate() for p in polygons]
        segs = [p.segments() for p in polygons]
        s = np.concatenate([st[t == VectorType.OBSTACLE] for st, _, t in segs])
        e = np.concatenate([en[t == VectorType.OBSTACLE] for _, en, t in segs])
        try:
            geom = geoms[0] if len(geoms) == 1 else shapely.union_all(geoms, grid_size=PRECISION_M)
            return self._merge_geometry(geom, s, e, options or MergeOptions())
        except shapely.errors.GEOSException as err:  # the last net: this map is unchanged
            n = len(polygons)
            raise GeometryError(f"GEOS failed to merge {n} polygon(s): {err}") from err

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
        obstacle = np.concatenate([x[2] for x in segs]) == VectorType.OBSTACLE
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
        front = [mine[i].vectors_of_type(VectorType.FRONTIER) for i in k]
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
        fronts = [c.vectors_of_type(VectorType.FRONTIER) for c in same]
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
        version = self.version + 1
        out = dict(self.cells)
        changed = set()
        for ix in idxs:
            cell = new_cells.get(ix)
            prev = self.cells.get(ix)
            if cell is None:
                if prev is not None:  # pragma: no cover - union never shrinks a region
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
        return MergeResult(GridPolyMap(self.cell_size, out, version), frozenset(changed))

    # -- deltas -------------------------------------------------------------------------

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

    # -- queries ------------------------------------------------------------------------

    def is_free(self, x: float, y: float) -> bool:
        """Is the point in explored free space (on a vector counts as inside)?"""
        cell = self.cells.get(self.cell_index(x, y))
        return cell is not None and bool(shapely.intersects_xy(cell.region, x, y))

    def is_free_many(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        out = np.zeros(len(xy), dtype=bool)
        for (i, j), rows in self._by_cell(xy):
            cell = self.cells.get((i, j))
            if cell is not None:
                out[rows] = shapely.intersects_xy(cell.region, xy[rows, 0], xy[rows, 1])
        return out

    def _by_cell(self, xy: np.ndarray) -> list[tuple[CellIndex, np.ndarray]]:
        """The points' rows grouped by the cell holding them."""
        if len(xy) == 0:
            return []
        ij = np.floor(xy / self.cell_size).astype(np.int64)
        # one int64 per cell (i high, j low), sorted: the groups in (i, j) order
        key = (ij[:, 0] << 32) + (ij[:, 1] + (1 << 31))
        order = np.argsort(key, kind="stable")
        first = np.r_[True, key[order][1:] != key[order][:-1]]
        starts = np.nonzero(first)[0]
        groups = np.split(order, starts[1:])
        cells = ij[order[starts]].tolist()
        return list(zip(map(tuple, cells), groups, strict=True))

    def locate(self, x: float, y: float) -> tuple[CellIndex, int] | None:
        """The cell and the index of the convex piece holding the point, or None."""
        ix = self.cell_index(x, y)
        cell = self.cells.get(ix)
        if cell is None:
            return None
        piece = cell.partition.locate(x, y)
        return None if piece is None else (ix, piece)

    def locate_many(self, xy: np.ndarray) -> list[tuple[CellIndex, int] | None]:
        """``locate`` for many points at once."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        out: list[tuple[CellIndex, int] | None] = [None] * len(xy)
        for ij, rows in self._by_cell(xy):
            cell = self.cells.get(ij)
            if cell is None:
                continue
            pieces = cell.partition.locate_many(xy[rows]).tolist()
            for r, piece in zip(rows.tolist(), pieces, strict=True):
                if piece >= 0:
                    out[r] = (ij, piece)
        return out

    def vectors(
        self, kinds: Iterable[VectorType] | None = None, cells: Iterable[CellIndex] | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All vectors (starts, ends, types), optionally filtered by type and cells."""
        src = (
            self.cells.values()
            if cells is None
            else [self.cells[c] for c in cells if c in self.cells]
        )
        parts = [c.vectors for c in src if c.polygons]
        if not parts:
            z = np.zeros((0, 2))
            return z, z, np.zeros(0, np.uint8)
        s, e, t = (np.concatenate([p[k] for p in parts]) for k in range(3))
        if kinds is not None:
            m = np.isin(t, [int(k) for k in kinds])
            s, e, t = s[m], e[m], t[m]
        return s, e, t

    @cached_property
    def _version_grid(self) -> tuple[int, int, np.ndarray]:
        """(lowest i, lowest j, the cells' versions over the map's index box; -1: none)."""
        if not self.cells:
            return 0, 0, np.full((0, 0), -1, dtype=np.int64)
        ij = np.array(list(self.cells), dtype=np.int64)
        lo = ij.min(axis=0)
        grid = np.full(tuple(ij.max(axis=0) - lo + 1), -1, dtype=np.int64)
        grid[ij[:, 0] - lo[0], ij[:, 1] - lo[1]] = [c.version for c in self.cells.values()]
        return int(lo[0]), int(lo[1]), grid

    def box_state(self, i0: int, j0: int, i1: int, j1: int) -> tuple[int, int]:
        """(cells, highest version) of the cells in the index box [i0, i1] x [j0, j1].

        A changed or new cell takes the map's next version, so from one version of the
        map to a later one this pair changes whenever a cell in the box was added,
        changed or removed: a cheap key for what was computed from the box's cells."""
        li, lj, grid = self._version_grid
        a, b = max(i0 - li, 0), min(i1 - li + 1, grid.shape[0])
        c, d = max(j0 - lj, 0), min(j1 - lj + 1, grid.shape[1])
        if a >= b or c >= d:
            return 0, -1
        sub = grid[a:b, c:d]
        return int(np.count_nonzero(sub >= 0)), int(sub.max())

    def cells_within(self, x: float, y: float, radius: float) -> list[CellIndex]:
        s = self.cell_size
        i0, i1 = math.floor((x - radius) / s), math.floor((x + radius) / s)
        j0, j1 = math.floor((y - radius) / s), math.floor((y + radius) / s)
        if (i1 - i0 + 1) * (j1 - j0 + 1) > 4 * len(self.cells) + 16:
            return [c for c in self.cells if i0 <= c[0] <= i1 and j0 <= c[1] <= j1]
        return [
            (i, j) for i in range(i0, i1 + 1) for j in range(j0, j1 + 1) if (i, j) in self.cells
        ]

    def nearest_obstacle_distance(self, x: float, y: float, max_distance: float = 10.0) -> float:
        """Distance (m) to the nearest obstacle vector; ``inf`` if none within max_distance."""
        s, e, _ = self.vectors([VectorType.OBSTACLE], self.cells_within(x, y, max_distance))
        if len(s) == 0:
            return math.inf
        d = float(point_segment_distance(np.array([x, y]), s, e).min())
        return d if d <= max_distance else math.inf

    # -- statistics ---------------------------------------------------------------------

    def explored_area(self) -> float:
        return float(sum(c.area for c in self.cells.values()))

    def explored_region(self) -> shapely.Geometry:
        """The whole explored free space as one shapely geometry (for metrics)."""
        regions = [c.region for c in self.cells.values() if c.polygons]
        if not regions:
            return shapely.Polygon()
        return shapely.union_all(regions, grid_size=PRECISION_M)

    def vector_counts(self) -> dict[str, int]:
        _, _, t = self.vectors()
        return {k.name.lower(): int(np.sum(t == k)) for k in VectorType}

    def polygon_count(self) -> int:
        return sum(len(c.polygons) for c in self.cells.values())

    def ring_count(self) -> int:
        return sum(len(p.rings()) for c in self.cells.values() for p in c.polygons)

    def bounds(self) -> tuple[float, float, float, float]:
        if not self.cells:
            return (0.0, 0.0, 0.0, 0.0)
        b = np.array([c.region.bounds for c in self.cells.values() if c.polygons])
        return (
            float(b[:, 0].min()),
            float(b[:, 1].min()),
            float(b[:, 2].max()),
            float(b[:, 3].max()),
        )


# ---------------------------------------------------------------------------------------
# Kernels
# ---------------------------------------------------------------------------------------


def _drop_thin_growth(
    old: np.ndarray, new: np.ndarray, width_m: float, walls: list[Cell] | None = None
) -> np.ndarray:
    """Regions that keep ``old`` where all of the growth is thinner than ``width_m``
    and lies along the cell's old walls (``walls``: the old cell of each region, whose
    obstacle vectors count; None: every thin growth is dropped).

    Only cells whose growth is small for their outline can be pure creep along walls
    (area below outline length x width); their growth is tested with a negative
    buffer. Cells that also gained real space keep all of it. Thin growth mostly more
    than ``width_m`` from the old walls fills a pocket between frontiers, not a wall:
    it is kept (a 4 cm sliver left across a door by a keyframe fan cut the room behind
    it off from the robots' navigation graph: the office, 1 robot, seed 3).
    """
    grew = shapely.area(new) - shapely.area(old)
    k = np.nonzero((grew > 0) & (grew <= shapely.length(old) * width_m) & ~shapely.is_empty(old))[0]
    if len(k) == 0:
        return new
    out = new.copy()
    extra, failed = _overlay(shapely.difference, new[k], old[k])
    thin = ~failed & shapely.is_empty(shapely.buffer(extra, -width_m / 2, quad_segs=2))
    if walls is not None and thin.any():
        t = np.nonzero(thin)[0]
        near = np.array([walls[k[j]].wall_zone(width_m) for j in t], dtype=object)
        along, bad = _overlay(shapely.intersection, extra[t], near)
        thin[t] = bad | (shapely.area(along) >= CREEP_SHARE * shapely.area(extra[t]))
    out[k[thin]] = old[k[thin]]
    return out


def _lines(starts: np.ndarray, ends: np.ndarray):
    """Segments as one MultiLineString (empty if none)."""
    if len(starts) == 0:
        return shapely.MultiLineString()
    return shapely.multilinestrings(np.stack([starts, ends], axis=1))


def fill_notches(cell: Cell, depth_m: float) -> Cell:
    """Remove shallow notches between obstacle vectors: cross-keyframe simplification.

    A wall seen by many keyframes is the union of slightly different fitted lines, so
    its outline is a chain of shallow V's (reflex vertices, measured: half the obstacle
    vectors of a simulated office shorter than 1 cm). A reflex vertex between two
    obstacle vectors, less than ``depth_m`` from the line joining its neighbours and
    not on the cell border, is removed: explored space only grows, by at most
    ``depth_m``, and the wall becomes the straight outer envelope. Repeated to a fixed
    point, so merging the same keyframe again still changes nothing.
    """
    if not (cell.vectors[2] == VectorType.OBSTACLE).any():
        return cell
    x0, y0, x1, y1 = cell.bounds
    changed = False
    polys = []
    for poly in cell.polygons:
        rings = []
        for ring in poly.rings():
            xy, ty = ring.xy, ring.types
            keep_all = True
            for _ in range(64):  # each pass removes every other candidate
                n = len(xy)
                if n <= 3:
                    break
                prev = np.r_[n - 1, np.arange(n - 1)]
                nxt = np.r_[np.arange(1, n), 0]
                u, w = xy[prev], xy[nxt]
                a, b = xy - u, w - xy
                uw = w - u
                L = np.hypot(uw[:, 0], uw[:, 1])
                cand = (
                    (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0] < 0)
                    & (ty == VectorType.OBSTACLE)
                    & (ty[prev] == VectorType.OBSTACLE)
                    & (np.abs(_cross(uw, xy - u)) < depth_m * np.where(L > 0, L, 1.0))
                    & (np.abs(xy[:, 0] - x0) > BORDER_TOL_M)
                    & (np.abs(xy[:, 0] - x1) > BORDER_TOL_M)
                    & (np.abs(xy[:, 1] - y0) > BORDER_TOL_M)
                    & (np.abs(xy[:, 1] - y1) > BORDER_TOL_M)
                )
                # never two neighbours in one pass: each removal must see fixed neighbours
                cand[1:] &= ~cand[:-1]
                if cand[0] and cand[-1]:
                    cand[-1] = False
                if not cand.any():
                    break
                xy, ty = xy[~cand], ty[~cand]
                keep_all = False
            if keep_all:
                rings.append(ring)
            else:
                rings.append(Ring(xy, ty))
                changed = True
        polys.append(TypedPolygon(rings[0], tuple(rings[1:])))
    if not changed:
        return cell
    out = Cell(cell.index, cell.size, tuple(polys), cell.version)
    if not out.region.is_valid or out.area < cell.area - 1e-12:
        return cell  # a removal crossed another part of the outline: keep the teeth
    return out


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


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def point_segment_distance(p: np.ndarray, s: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Distances from point(s) ``p`` (2,) or (n,2) to segments s->e (n,2)."""
    d = e - s
    L2 = np.einsum("ij,ij->i", d, d)
    L2 = np.where(L2 > 0, L2, 1.0)
    t = np.clip(np.einsum("ij,ij->i", p - s, d) / L2, 0.0, 1.0)
    q = s + t[:, None] * d
    return np.hypot(*(p - q).T)


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
    has_own = np.zeros(len(target), dtype=bool)
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


def _clip(geom, bounds) -> shapely.Geometry:
    """``geom`` clipped to a rectangle. GEOS's fast clip raises on a ring that collapses
    to 3 points (a scan corner exactly on a cell border); the exact intersection does
    not."""
    try:
        return shapely.clip_by_rect(geom, *bounds)
    except shapely.errors.GEOSException:
        return shapely.intersection(geom, shapely.box(*bounds), grid_size=PRECISION_M)


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


def _typed_cells(
    idxs: list[CellIndex],
    regions: np.ndarray,
    cell_size: float,
    src_starts: np.ndarray,
    src_ends: np.ndarray,
    new_regions: Mapping[CellIndex, shapely.Geometry],
    old_cells: Mapping[CellIndex, Cell],
    obstacle_snap_m: float = 0.0,
    snap_beside_m: tuple[float, float] = (0.0, 0.0),
) -> dict[CellIndex, Cell]:
    """Turn merged cell regions into cells of canonical typed rings.

    Every vector of a result ring is a piece of some input vector (GEOS keeps input
    vertices), so its type is inherited: sector if it lies on the cell border with
    explored space across it; else obstacle if it lies along a source obstacle vector
    (obstacle wins over frontier); else frontier.
    """
    polys, poly_cell = _polygon_parts(regions)
    cell_ij = np.array(idxs, dtype=np.int64).reshape(-1, 2)

    def sectors(a, b, mid, e_owner, types):
        ij = cell_ij[e_owner]
        x0 = ij[:, 0] * cell_size
        y0 = ij[:, 1] * cell_size
        on = lambda v, c: np.abs(v - c) <= BORDER_TOL_M  # noqa: E731
        # per side: vectors on it, the neighbour across, the border line (axis, at)
        cand, nb, axis, line = [], [], [], []
        for side, ax, at, step in (
            (on(a[:, 0], x0) & on(b[:, 0], x0), 0, x0, (-1, 0)),
            (on(a[:, 0], x0 + cell_size) & on(b[:, 0], x0 + cell_size), 0, x0 + cell_size, (1, 0)),
            (on(a[:, 1], y0) & on(b[:, 1], y0), 1, y0, (0, -1)),
            (on(a[:, 1], y0 + cell_size) & on(b[:, 1], y0 + cell_size), 1, y0 + cell_size, (0, 1)),
        ):
            k = np.nonzero(side)[0]
            cand.append(k)
            nb.append(ij[k] + np.array(step))
            axis.append(np.full(len(k), ax))
            line.append(at[k])
        cand = np.concatenate(cand)
        if len(cand) == 0:
            return
        nb, axis, line = np.concatenate(nb), np.concatenate(axis), np.concatenate(line)
        # each neighbour's side once: where its explored space reaches the border
        keys = list(zip(map(tuple, nb.tolist()), axis.tolist(), line.tolist(), strict=True))
        uniq = {key: n for n, key in enumerate(dict.fromkeys(keys))}
        which = np.array([uniq[key] for key in keys])
        first = np.unique(which, return_index=True)[1]
        geoms = [_region_at(key[0], new_regions, old_cells) for key in uniq]
        lo, hi, owner = _border_cover(geoms, axis[first], line[first])
        # explored space across the border along all of the vector but for SECTOR_GAP_M
        # (SECTOR_TOL_M absorbs rounding between the two sides); free space across the
        # border makes a sector even where an obstacle vector once lay on the border:
        # the wall was not there (both sides are free)
        v_lo = np.minimum(a[cand, 1 - axis], b[cand, 1 - axis])
        v_hi = np.maximum(a[cand, 1 - axis], b[cand, 1 - axis])
        n_iv = np.bincount(owner, minlength=len(uniq))
        at_iv = np.concatenate([[0], np.cumsum(n_iv)[:-1]])
        reps = n_iv[which]
        if reps.sum() == 0:
            return
        c = np.repeat(np.arange(len(cand)), reps)  # every (vector, interval across) pair
        iv = np.repeat(at_iv[which] - np.concatenate([[0], np.cumsum(reps)[:-1]]), reps)
        iv += np.arange(len(c))
        over = np.minimum(hi[iv], v_hi[c]) - np.maximum(lo[iv], v_lo[c])
        touch = np.zeros(len(cand), dtype=bool)
        touch[c[over >= 0]] = True
        covered = np.bincount(c, weights=over.clip(0), minlength=len(cand))
        types[cand[touch & (v_hi - v_lo - covered <= SECTOR_GAP_M)]] = VectorType.SECTOR

    out = _typed_polygons(
        polys, poly_cell, src_starts, src_ends, sectors, obstacle_snap_m, snap_beside_m
    )
    cells = [Cell(idxs[k], cell_size, tuple(tp)) for k, tp in out.items() if tp]
    for c, g in zip(cells, _build_regions(cells), strict=True):
        c.__dict__["region"] = g  # fill the cached property in one vectorised pass
    return {c.index: c for c in cells}


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


def _typed_polygons(
    polys: np.ndarray,
    owner: np.ndarray,
    src_starts: np.ndarray,
    src_ends: np.ndarray,
    sectors=None,
    obstacle_snap_m: float = 0.0,
    snap_beside_m: tuple[float, float] = (0.0, 0.0),
) -> dict[int, list[TypedPolygon]]:
    """Typed, canonical polygons from oriented shapely polygons, grouped by ``owner``.

    Vectors along a source obstacle vector are obstacles (also, with
    ``obstacle_snap_m`` > 0, frontiers running along one within that distance, and with
    ``snap_beside_m`` = (behind, in front) not zero, frontiers lying beside obstacles
    within those distances all along);
    ``sectors(a, b, mid, owner, types)`` may then mark sectors; every other vector is a
    frontier.
    """
    if len(polys) == 0:
        return {}
    rings, ring_poly = shapely.get_rings(polys, return_index=True)
    coords, ring_of = shapely.get_coordinates(rings, return_index=True)
    # vector k runs from coords[k] to coords[k+1] within one ring (rings are closed)
    same = ring_of[1:] == ring_of[:-1]
    a, b = coords[:-1][same], coords[1:][same]
    e_ring = ring_of[:-1][same]
    types = np.full(len(a), VectorType.FRONTIER, dtype=np.uint8)
    tree = _segment_tree(src_starts, src_ends)  # one index of the sources for every test
    obstacle = _obstacle_mask(a, b, src_starts, src_ends, tree, obstacle_snap_m, snap_beside_m)
    types[obstacle] = VectorType.OBSTACLE
    if sectors is not None:
        sectors(a, b, 0.5 * (a + b), owner[ring_poly[e_ring]], types)

    # canonical rings: drop zero-length vectors and collinear vertices between vectors
    # of one type, start each ring at its lowest (x, y) vertex: equal regions give
    # equal rings, whatever the history of merges
    q = np.rint(a * UNITS_PER_M).astype(np.int64)
    keep = _ring_mask(q, e_ring, lambda q, nx, pv: np.any(q != q[nx], axis=1))
    a, q, types, e_ring = a[keep], q[keep], types[keep], e_ring[keep]

    def straight(q, nx, pv):
        u, v = q - q[pv], q[nx] - q
        cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
        dot = u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1]
        return ~((cross == 0) & (dot > 0) & (types == types[pv]))

    keep = _ring_mask(q, e_ring, straight)
    a, q, types, e_ring = a[keep], q[keep], types[keep], e_ring[keep]
    if len(a) == 0:
        return {}
    ring_ids, starts_at, counts = np.unique(e_ring, return_index=True, return_counts=True)
    # rotate each ring to start at its lexicographically lowest vertex
    order = np.lexsort((q[:, 1], q[:, 0], e_ring))
    first = order[np.searchsorted(e_ring[order], ring_ids)]
    s_rep, n_rep = np.repeat(starts_at, counts), np.repeat(counts, counts)
    local = np.arange(len(a)) - s_rep
    perm = s_rep + (local + np.repeat(first - starts_at, counts)) % n_rep
    a, types = a[perm], types[perm]
    x, y = a[:, 0], a[:, 1]
    nxt = s_rep + (local + 1) % n_rep
    area2 = np.add.reduceat(x * y[nxt] - x[nxt] * y, starts_at)

    grouped: dict[int, list[list[Ring]]] = {}
    shell_slot: dict[int, int] = {}
    poly_of_ring = ring_poly[ring_ids]
    for r in range(len(ring_ids)):
        lo, n = int(starts_at[r]), int(counts[r])
        if n < 3:
            continue
        p = int(poly_of_ring[r])
        plist = grouped.setdefault(int(owner[p]), [])
        ring = Ring(a[lo : lo + n], types[lo : lo + n])
        if p not in shell_slot:  # get_rings lists each polygon's shell first
            if area2[r] <= 0:  # a collapsed shell: the polygon is a sliver
                shell_slot[p] = -1
                continue
            shell_slot[p] = len(plist)
            plist.append([ring])
        elif shell_slot[p] >= 0:
            plist[shell_slot[p]].append(ring)
    out = {}
    for k, plist in grouped.items():
        tp = [TypedPolygon(rs[0], tuple(sorted(rs[1:], key=_ring_key))) for rs in plist]
        tp.sort(key=lambda p: _ring_key(p.shell))
        out[k] = tp
    return out


def _obstacle_mask(
    a: np.ndarray,
    b: np.ndarray,
    src_starts: np.ndarray,
    src_ends: np.ndarray,
    tree: shapely.STRtree | None,
    obstacle_snap_m: float = 0.0,
    snap_beside_m: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Vectors a->b that are obstacles by the source obstacle vectors (``tree`` is their
    ``_segment_tree``): along one, or with the snap distances not zero, running along one
    within ``obstacle_snap_m`` or beside obstacles all along (``_typed_polygons``)."""
    mid = 0.5 * (a + b)
    hit = _along_obstacles(a, b, mid, src_starts, src_ends, tree=tree)
    if obstacle_snap_m > 0:
        front = np.nonzero(~hit)[0]
        near = _along_obstacles(
            a[front],
            b[front],
            mid[front],
            src_starts,
            src_ends,
            obstacle_snap_m,
            SNAP_ANGLE_DEG,
            tree,
            within_ends=True,
        )
        hit[front[near]] = True
    if max(snap_beside_m) > 0:
        front = np.nonzero(~hit)[0]
        beside = _beside_obstacles(
            a[front],
            b[front],
            src_starts,
            src_ends,
            max(snap_beside_m[0], MATCH_TOL_M),
            max(snap_beside_m[1], MATCH_TOL_M),
            SNAP_ANGLE_DEG,
            tree,
        )
        hit[front[beside]] = True
    return hit


def _segment_tree(starts: np.ndarray, ends: np.ndarray) -> shapely.STRtree | None:
    if len(starts) == 0:
        return None
    return shapely.STRtree(shapely.linestrings(np.stack([starts, ends], axis=1)))


def _along_obstacles(
    a,
    b,
    mid,
    src_starts,
    src_ends,
    tol: float = MATCH_TOL_M,
    max_angle_deg: float = 30.0,
    tree: shapely.STRtree | None = None,
    within_ends: bool = False,
    owners: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Vectors a->b lying along a source obstacle vector (within ``tol`` of its line,
    the middle within ``tol`` of the vector), in the same direction (within
    ``max_angle_deg``). With ``within_ends`` neither end may lie past the source's ends
    by more than ``tol``: a frontier that continues a wall's line past the wall's end
    (the view past a door jamb) is not snapped to that wall. ``tree``: the sources'
    ``_segment_tree``, if the caller has it. ``owners`` (one id per vector, one per
    source): only a source of the vector's own id counts (many cells in one call)."""
    hit = np.zeros(len(a), dtype=bool)
    if len(src_starts) == 0 or len(a) == 0:
        return hit
    tree = _segment_tree(src_starts, src_ends) if tree is None else tree
    k, j = tree.query(shapely.points(mid), predicate="dwithin", distance=tol)
    if owners is not None:
        same = owners[0][k] == owners[1][j]
        k, j = k[same], j[same]
    if len(k) == 0:
        return hit
    d = src_ends[j] - src_starts[j]
    L = np.hypot(d[:, 0], d[:, 1])
    n = d / np.where(L > 0, L, 1.0)[:, None]
    da = np.abs(_cross(n, a[k] - src_starts[j]))
    db = np.abs(_cross(n, b[k] - src_starts[j]))
    within = True
    if within_ends:  # both ends' positions along the source, within its extent
        ta = np.einsum("ij,ij->i", a[k] - src_starts[j], n)
        tb = np.einsum("ij,ij->i", b[k] - src_starts[j], n)
        within = (np.minimum(ta, tb) >= -tol) & (np.maximum(ta, tb) <= L + tol)
    u = b[k] - a[k]
    lu = np.hypot(u[:, 0], u[:, 1])
    # same direction within 30 degrees: millimetre-long vectors made by rounding
    # would otherwise match any nearby obstacle
    same_dir = np.einsum("ij,ij->i", u, n) >= np.cos(np.radians(max_angle_deg)) * lu
    ok = (L > 0) & (da <= tol) & (db <= tol) & within & same_dir & (lu > 0)
    hit[np.unique(k[ok])] = True
    return hit


def _beside_obstacles(
    a,
    b,
    src_starts,
    src_ends,
    behind_m: float,
    front_m: float,
    max_angle_deg: float,
    tree: shapely.STRtree | None = None,
) -> np.ndarray:
    """Vectors a->b every point of which (sampled every ``BESIDE_STEP_M``) lies beside a
    source obstacle vector running the same way (within ``max_angle_deg``), at most
    ``behind_m`` behind it (on its unexplored side) or ``front_m`` in front of it. A
    frontier across a doorway is not: its middle lies beside no wall."""
    hit = np.zeros(len(a), dtype=bool)
    if len(src_starts) == 0 or len(a) == 0:
        return hit
    tree = _segment_tree(src_starts, src_ends) if tree is None else tree
    reach = max(behind_m, front_m)
    # only vectors with both ends near some obstacle can lie beside obstacles all along
    ends = shapely.points(np.concatenate([a, b]))
    near = np.zeros(2 * len(a), dtype=bool)
    near[tree.query(ends, predicate="dwithin", distance=reach)[0]] = True
    cand = np.nonzero(near[: len(a)] & near[len(a) :])[0]
    if len(cand) == 0:
        return hit
    u = b[cand] - a[cand]
    lu = np.hypot(u[:, 0], u[:, 1])
    m = np.maximum(1, np.ceil(lu / BESIDE_STEP_M)).astype(int) + 1  # samples, both ends
    v = np.repeat(np.arange(len(cand)), m)
    first = np.cumsum(m) - m
    t = (np.arange(len(v)) - np.repeat(first, m)) / (m[v] - 1)
    pts = a[cand][v] + t[:, None] * u[v]
    k, j = tree.query(shapely.points(pts), predicate="dwithin", distance=reach)
    d = src_ends[j] - src_starts[j]
    L = np.hypot(d[:, 0], d[:, 1])
    n = d / np.where(L > 0, L, 1.0)[:, None]
    rel = pts[k] - src_starts[j]
    side = _cross(n, rel)  # > 0: in front of the obstacle (its explored side)
    along = np.einsum("ij,ij->i", rel, n)
    same_dir = np.einsum("ij,ij->i", u[v[k]], n) >= np.cos(np.radians(max_angle_deg)) * lu[v[k]]
    ok = (
        (L > 0)
        & (side >= -behind_m)
        & (side <= front_m)
        & (along >= -BESIDE_ENDS_M)
        & (along <= L + BESIDE_ENDS_M)
        & same_dir
    )
    covered = np.zeros(len(pts), dtype=bool)
    covered[k[ok]] = True
    hit[cand] = np.logical_and.reduceat(covered, first) & (lu > 0)
    return hit


def _ring_mask(q: np.ndarray, ring: np.ndarray, rule) -> np.ndarray:
    """Vertices to keep: ``rule(q, next_index, prev_index)`` per vertex of each ring."""
    if len(q) == 0:
        return np.zeros(0, dtype=bool)
    _, starts, counts = np.unique(ring, return_index=True, return_counts=True)
    s = np.repeat(starts, counts)
    n = np.repeat(counts, counts)
    local = np.arange(len(q)) - s
    nx = s + (local + 1) % n
    pv = s + (local - 1) % n
    return rule(q, nx, pv)


def _ring_key(r: Ring) -> tuple[float, float]:
    return (float(r.xy[0, 0]), float(r.xy[0, 1]))
