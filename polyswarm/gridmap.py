"""A standard log-odds occupancy-grid mapper: the map a ROS user would share.

The baseline of the bandwidth comparison: the same scans and poses that PolySLAM used go
into a 5 cm grid by ray casting (free along each beam, occupied at its end), and the
grid is published as nav_msgs/OccupancyGrid (-1 unknown, 0 free, 100 occupied) or as
map_msgs/OccupancyGridUpdate bounding-box deltas.

    g = LogOddsGrid(bounds=(x0, y0, x1, y1), resolution_m=0.05)
    g.integrate(scan, pose)
    box = g.changes()          # trinary cells changed since the last call: (row0, col0, data)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from polyswarm.errors import MapError
from polyswarm.occupancy import FREE, OCCUPIED, UNKNOWN
from polyswarm.scan import LaserScan

# log-odds increments and limits (the usual values of gmapping / Thrun et al.)
L_OCC = 0.85  # a beam end: p = 0.7
L_FREE = -0.4  # a cell a beam passes: p = 0.4
L_MIN, L_MAX = -2.0, 3.5  # clamping keeps the grid responsive
L_OCC_THRESH = math.log(0.65 / 0.35)  # occupied above p = 0.65 (map_server default)
L_FREE_THRESH = math.log(0.196 / 0.804)  # free below p = 0.196 (map_server default)
MAX_GRID_CELLS = 64_000_000  # a grid larger than this (256 MB of float32) is refused


@dataclass(frozen=True)
class GridBox:
    """Trinary cells of a rectangle of the grid: rows ``row0..``, columns ``col0..``."""

    row0: int
    col0: int
    data: np.ndarray  # (rows, cols) int8


class LogOddsGrid:
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
        self.logodds = np.zeros((rows, cols), dtype=np.float32)
        self.free_range_m = free_range_m  # beams with no return clear this far
        self._published = np.full((rows, cols), UNKNOWN, dtype=np.int8)

    @property
    def shape(self) -> tuple[int, int]:
        return self.logodds.shape

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
        # free cells: samples every half cell along each beam, short of its end
        step = 0.5 * self.res
        n = np.ceil(length / step).astype(int)
        beam = np.repeat(np.arange(len(a)), n)
        offs = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        d = offs * step
        inside = d < length[beam] - self.res  # the end cell is not cleared
        beam, d = beam[inside], d[inside]
        free = self._cells(sx + d * np.cos(a[beam]), sy + d * np.sin(a[beam]))
        ends = self._cells(sx + length[hit] * np.cos(a[hit]), sy + length[hit] * np.sin(a[hit]))
        lo = self.logodds.reshape(-1)
        free = np.setdiff1d(free, ends)  # a cell hit in this scan is not also cleared
        lo[free] = np.maximum(lo[free] + L_FREE, L_MIN)
        lo[ends] = np.minimum(lo[ends] + L_OCC, L_MAX)

    def _cells(self, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        rows, cols = self.shape
        c = np.floor((xs - self.origin[0]) / self.res).astype(np.int64)
        r = np.floor((ys - self.origin[1]) / self.res).astype(np.int64)
        ok = (c >= 0) & (c < cols) & (r >= 0) & (r < rows)
        return np.unique(r[ok] * cols + c[ok])

    def trinary(self) -> np.ndarray:
        """The grid as published: -1 unknown, 0 free, 100 occupied (row 0 = lowest y)."""
        out = np.full(self.shape, UNKNOWN, dtype=np.int8)
        out[self.logodds < L_FREE_THRESH] = FREE
        out[self.logodds > L_OCC_THRESH] = OCCUPIED
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
