"""The occupancy grid a ROS user would share, built as gmapping builds it.

The baseline of the bandwidth comparison: the same scans and poses that PolySLAM used go
into a 5 cm grid by ray casting, and the grid is published as nav_msgs/OccupancyGrid
(-1 unknown, 0 free, 100 occupied) or as map_msgs/OccupancyGridUpdate bounding-box
deltas. Cells count as gmapping's do (``GMapping::PointAccumulator``): every beam that
passes a cell is a visit, every beam that ends in it a hit and a visit; slam_gmapping
publishes a cell never visited as -1, as 100 when hits / visits exceed ``~occ_thresh``
(default 0.25), else as 0. So one pass makes a cell free (a log-odds grid with -0.4 per
miss against map_server's free threshold needed four).

    g = CountingGrid(bounds=(x0, y0, x1, y1), resolution_m=0.05)
    g.integrate(scan, pose)
    box = g.changes()          # trinary cells changed since the last call: (row0, col0, data)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from polyswarm.errors import MapError
from polyswarm.grids.occupancy import FREE, OCCUPIED, UNKNOWN
from polyswarm.slam.scan import LaserScan

OCC_THRESH = 0.25  # slam_gmapping's ~occ_thresh default: occupied above this hit share
MAX_GRID_CELLS = 64_000_000  # a grid larger than this (512 MB of two int32 counts) is refused


@dataclass(frozen=True)
class GridBox:
    """Trinary cells of a rectangle of the grid: rows ``row0..``, columns ``col0..``."""

    row0: int
    col0: int
    data: np.ndarray  # (rows, cols) int8


class CountingGrid:
    def __init__(
        self,
        bounds: tuple[float, float, float, float],
        resolution_m: float = 0.05,
        free_range_m: float = 3.0,
    ) -> None:
        x0, y0, x1, y1 = bounds
        self.res = float(resolution_m)
        self.origin = (math.floor(x0 / self.res) * self.res, math.floor(y0 / self.res) * self.res)
        cols = math.ceil((x1 - self.origin[0]) / self.res) + 1
        rows = math.ceil((y1 - self.origin[1]) / self.res) + 1
        if rows * cols > MAX_GRID_CELLS or rows <= 0 or cols <= 0:
            raise MapError(f"grid of {rows} x {cols} cells refused")
        self.hits = np.zeros((rows, cols), dtype=np.int32)
        self.visits = np.zeros((rows, cols), dtype=np.int32)
        self.free_range_m = free_range_m  # beams with no return clear this far
        self._published = np.full((rows, cols), UNKNOWN, dtype=np.int8)

    @property
    def shape(self) -> tuple[int, int]:
        return self.hits.shape

    @property
    def size(self) -> int:
        return self.hits.size

    def integrate(self, scan: LaserScan, pose, mount=(0.0, 0.0, 0.0)) -> None:
        """Ray-cast one scan taken at robot ``pose`` (x, y, theta) into the grid."""
        x, y, th = (float(v) for v in pose)
        mx, my, myaw = mount
        sx = x + math.cos(th) * mx - math.sin(th) * my
        sy = y + math.sin(th) * mx + math.cos(th) * my
        r = np.asarray(scan.ranges, dtype=float)
        a = scan.angles + th + myaw
        hit = np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max)
        miss = np.isinf(r) & (r > 0)
        length = np.where(hit, r, np.where(miss, self.free_range_m, 0.0))
        keep = length > 0
        a, length, hit = a[keep], length[keep], hit[keep]
        # passed cells: samples every half cell along each beam, short of its end
        step = 0.5 * self.res
        n = np.ceil(length / step).astype(int)
        beam = np.repeat(np.arange(len(a)), n)
        offs = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        d = offs * step
        inside = d < length[beam] - 0.5 * self.res  # up to the end cell (the hit)
        beam, d = beam[inside], d[inside]
        passed = self._cells(sx + d * np.cos(a[beam]), sy + d * np.sin(a[beam]))
        ends = self._cells(sx + length[hit] * np.cos(a[hit]), sy + length[hit] * np.sin(a[hit]))
        passed = np.setdiff1d(passed, ends)  # a cell hit in this scan is not also passed
        v, h = self.visits.reshape(-1), self.hits.reshape(-1)
        v[passed] += 1
        v[ends] += 1
        h[ends] += 1

    def _cells(self, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        rows, cols = self.shape
        c = np.floor((xs - self.origin[0]) / self.res).astype(np.int64)
        r = np.floor((ys - self.origin[1]) / self.res).astype(np.int64)
        ok = (c >= 0) & (c < cols) & (r >= 0) & (r < rows)
        return np.unique(r[ok] * cols + c[ok])

    def trinary(self) -> np.ndarray:
        """The grid as published: -1 unknown, 0 free, 100 occupied (row 0 = lowest y)."""
        out = np.full(self.shape, UNKNOWN, dtype=np.int8)
        seen = self.visits > 0
        occupied = self.hits > OCC_THRESH * self.visits
        out[seen & ~occupied] = FREE
        out[seen & occupied] = OCCUPIED
        return out

    def changes(self) -> GridBox | None:
        """The bounding box of the cells whose published value changed since the last
        call (what an OccupancyGridUpdate carries); None when nothing changed."""
        now = self.trinary()
        diff = now != self._published
        if not diff.any():
            return None
        rows = np.nonzero(diff.any(axis=1))[0]
        cols = np.nonzero(diff.any(axis=0))[0]
        r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
        self._published = now
        return GridBox(int(r0), int(c0), now[r0:r1, c0:c1].copy())

    def known_area_m2(self) -> float:
        t = self.trinary()
        return float((t != UNKNOWN).sum()) * self.res**2

    def free_area_m2(self) -> float:
        return float((self.trinary() == FREE).sum()) * self.res**2
