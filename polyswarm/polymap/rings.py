"""Vectors, rings and typed polygons: the geometry a PolyMap is made of, and the
constants of its precision grid."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
import shapely
from shapely.geometry import Polygon

from polyswarm.errors import (
    InvalidPolygonError,
)

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


# The types as plain ints, for comparisons with numpy arrays on hot paths: numpy asks an
# IntEnum member for its array protocol through the enum's slow ``__getattr__``, which
# made ``types == VectorType.OBSTACLE`` five times slower than ``types == OBSTACLE``
# (200 vectors: 7.7 against 1.6 us; 1.6 million such tests on the maze's coverage route)
OBSTACLE, FRONTIER, SECTOR = (int(t) for t in VectorType)


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


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
            if np.any(ring.types > SECTOR):
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


def _lines(starts: np.ndarray, ends: np.ndarray):
    """Segments as one MultiLineString (empty if none)."""
    if len(starts) == 0:
        return shapely.MultiLineString()
    return shapely.multilinestrings(np.stack([starts, ends], axis=1))


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
