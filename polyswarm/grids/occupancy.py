"""Occupancy grids with nav_msgs/OccupancyGrid semantics.

``data[row, col]`` with row 0 at the origin (lowest y), values -1 unknown, 0 free,
100 occupied; cell (row, col) covers
``[origin_x + col*res, origin_x + (col+1)*res] x [origin_y + row*res, ...]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyswarm.errors import DataFormatError

UNKNOWN = -1
FREE = 0
OCCUPIED = 100


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    data: np.ndarray  # (rows, cols) int8
    resolution: float  # metres per cell
    origin: tuple[float, float] = (0.0, 0.0)  # world position of the corner of cell (0, 0)

    def __post_init__(self) -> None:
        d = np.asarray(self.data)
        if d.ndim != 2 or d.size == 0:
            raise DataFormatError(f"occupancy grid must be a non-empty 2D array, got {d.shape}")
        if not np.isin(d, (UNKNOWN, FREE, OCCUPIED)).all():
            raise DataFormatError("occupancy grid values must be -1, 0 or 100")
        if not (self.resolution > 0 and np.isfinite(self.resolution)):
            raise DataFormatError(f"resolution must be positive, got {self.resolution}")
        d = d.astype(np.int8)
        d.setflags(write=False)
        object.__setattr__(self, "data", d)
        object.__setattr__(self, "origin", (float(self.origin[0]), float(self.origin[1])))

    @property
    def shape(self) -> tuple[int, int]:
        return self.data.shape  # type: ignore[return-value]

    @property
    def free(self) -> np.ndarray:
        return self.data == FREE

    @property
    def occupied(self) -> np.ndarray:
        return self.data == OCCUPIED

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(min_x, min_y, max_x, max_y) in metres."""
        r, c = self.shape
        x0, y0 = self.origin
        return (x0, y0, x0 + c * self.resolution, y0 + r * self.resolution)

    def cell_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """x of every column centre and y of every row centre."""
        r, c = self.shape
        x = self.origin[0] + (np.arange(c) + 0.5) * self.resolution
        y = self.origin[1] + (np.arange(r) + 0.5) * self.resolution
        return x, y

    def world_to_cell(self, x: float, y: float) -> tuple[int, int]:
        return (
            int(np.floor((y - self.origin[1]) / self.resolution)),
            int(np.floor((x - self.origin[0]) / self.resolution)),
        )

    def upsample(self, factor: int) -> OccupancyGrid:
        """The same map on a grid ``factor`` times finer (nearest neighbour)."""
        if factor < 1:
            raise DataFormatError("upsampling factor must be >= 1")
        d = np.repeat(np.repeat(self.data, factor, axis=0), factor, axis=1)
        return OccupancyGrid(d, self.resolution / factor, self.origin)
