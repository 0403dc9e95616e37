"""A cell of the map's grid: the explored space inside one square, as typed rings."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import shapely

from polyswarm.polymap.regions import _build_regions
from polyswarm.polymap.rings import (
    SECTOR,
    CellIndex,
    TypedPolygon,
    VectorType,
    _lines,
    _readonly,
)


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

    def __reduce__(self):
        # pickled (to and from worker processes) as its content and its region, not the
        # other caches: a delta's cells with their partitions and wall zones pickled 12
        # times larger and took 18 times longer to unpickle (maze, 50 cells: 3.7 ms)
        return (
            _cell,
            (self.index, self.size, self.polygons, self.version, self.__dict__.get("region")),
        )

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
            (ring.types == SECTOR).all()
            and abs(ring.signed_area - self.size * self.size) <= 1e-9 * self.size * self.size
        )

    @cached_property
    def obstacle_vectors(self) -> tuple[np.ndarray, np.ndarray]:
        return self.vectors_of_type(VectorType.OBSTACLE)

    @cached_property
    def frontier_vectors(self) -> tuple[np.ndarray, np.ndarray]:
        """(starts, ends) of the frontier vectors (kept: trimming asks every cell a
        keyframe reaches, and most cells are the same from one keyframe to the next)."""
        return self.vectors_of_type(VectorType.FRONTIER)

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
        m = t == int(kind)
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


def _cell(index, size, polygons, version, region) -> Cell:
    """A cell unpickled (``Cell.__reduce__``), with its region if it had one."""
    c = Cell(index, size, polygons, version)
    if region is not None:
        c.__dict__["region"] = region
    return c
