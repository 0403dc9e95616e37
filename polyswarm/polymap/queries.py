"""Questions to a map: free space at points, convex pieces, vectors, area, bounds."""

from __future__ import annotations

import math
from collections.abc import Iterable
from functools import cached_property

import numpy as np
import shapely

from polyswarm.polymap.partition import partition_of
from polyswarm.polymap.rings import PRECISION_M, CellIndex, VectorType, point_segment_distance


class MapQueries:
    """GridPolyMap's questions (a mixin): is a point explored, in which convex piece,
    which vectors, how much area."""

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
        piece = partition_of(cell).locate(x, y)
        return None if piece is None else (ix, piece)

    def locate_many(self, xy: np.ndarray) -> list[tuple[CellIndex, int] | None]:
        """``locate`` for many points at once."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        out: list[tuple[CellIndex, int] | None] = [None] * len(xy)
        for ij, rows in self._by_cell(xy):
            cell = self.cells.get(ij)
            if cell is None:
                continue
            pieces = partition_of(cell).locate_many(xy[rows]).tolist()
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
