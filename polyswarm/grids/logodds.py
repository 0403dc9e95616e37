"""The reference for a map built from real scans: a log-odds occupancy grid of the same
scans at the same poses, as a grid SLAM package builds it at its usual settings.

Every beam with a return lowers the log-odds of the cells it crosses by ``MISS`` and
raises the cell it ends in by ``HIT`` (OctoMap's defaults: 0.7 and 0.4 as
probabilities); a beam without a return updates nothing (it may have met a dark or
glass surface). Log-odds are clamped to ``CLAMP`` so that a cell can change its mind.
A cell is occupied above 0, free below 0, unknown where no beam crossed or hit it.

    grid = LogOddsGrid.from_scans(scans, poses, mount, out_of_range="zero")
    grid.occupied, grid.free, grid.touched      # (rows, cols) bool, row 0 at grid.origin
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from polyswarm.errors import MapError
from polyswarm.slam.scan import LaserScan, beam_angles, classify

HIT = 0.85  # log-odds added where a return ends (p = 0.7)
MISS = -0.4  # log-odds added where a return's beam passed (p = 0.4)
CLAMP = (-2.0, 3.5)  # log-odds bounds (p 0.12 and 0.97, OctoMap's)
RESOLUTION_M = 0.05  # the usual grid of a 2D SLAM package
STEP_SHARE = 0.25  # beams are sampled every quarter cell: no cell they cross is skipped
MAX_CELLS = 64_000_000  # a grid larger than this is refused (256 MB of float32)


@dataclass(frozen=True, eq=False)
class LogOddsGrid:
    log_odds: np.ndarray  # (rows, cols) float32
    touched: np.ndarray  # (rows, cols) bool: a beam with a return crossed or ended here
    resolution: float  # metres per cell
    origin: tuple[float, float]  # world position of the corner of cell (0, 0)

    @property
    def occupied(self) -> np.ndarray:
        return self.touched & (self.log_odds > 0)

    @property
    def free(self) -> np.ndarray:
        return self.touched & (self.log_odds < 0)

    def centres(self, mask: np.ndarray) -> np.ndarray:
        """World (x, y) of the centres of the cells ``mask`` selects."""
        r, c = np.nonzero(mask)
        return np.stack(
            [
                self.origin[0] + (c + 0.5) * self.resolution,
                self.origin[1] + (r + 0.5) * self.resolution,
            ],
            axis=1,
        )

    @classmethod
    def from_scans(
        cls,
        scans: list[LaserScan],
        poses: np.ndarray,
        mount=(0.0, 0.0, 0.0, False),
        out_of_range: str = "inf",
        resolution_m: float = RESOLUTION_M,
    ) -> LogOddsGrid:
        """The grid of ``scans``, each taken at robot pose ``poses[k]`` (x, y, theta) with
        the lidar at ``mount`` = (x, y, yaw, upside_down) on the robot."""
        rays = [
            _rays(s, p, mount, out_of_range) for s, p in zip(scans, np.asarray(poses), strict=True)
        ]
        ends = np.concatenate([r[1] for r in rays]) if rays else np.zeros((0, 2))
        origins = np.array([r[0] for r in rays]) if rays else np.zeros((0, 2))
        pts = np.vstack([ends, origins]) if len(ends) else origins
        if len(pts) == 0:
            raise MapError("no scan to build a grid from")
        lo = np.floor(pts.min(axis=0) / resolution_m) * resolution_m - resolution_m
        hi = pts.max(axis=0) + 2 * resolution_m
        cols, rows = (np.ceil((hi - lo) / resolution_m)).astype(int)
        if rows * cols > MAX_CELLS:
            raise MapError(f"a grid of {rows} x {cols} cells is refused")
        lo_t = (float(lo[0]), float(lo[1]))
        L = np.zeros(rows * cols, dtype=np.float32)
        touched = np.zeros(rows * cols, dtype=bool)
        for origin, end in rays:
            passed, hit = _cells_of_beams(origin, end, lo_t, resolution_m, rows, cols)
            passed = np.setdiff1d(passed, hit, assume_unique=True)  # a hit cell wins
            L[passed] = np.maximum(L[passed] + MISS, CLAMP[0])
            L[hit] = np.minimum(L[hit] + HIT, CLAMP[1])
            touched[passed] = True
            touched[hit] = True
        return cls(L.reshape(rows, cols), touched.reshape(rows, cols), resolution_m, lo_t)


def _rays(scan: LaserScan, pose, mount, out_of_range: str) -> tuple[np.ndarray, np.ndarray]:
    """The sensor's world position and the world ends of the scan's returns."""
    x, y, th = (float(v) for v in pose)
    valid = classify(scan, out_of_range)[0]
    r = np.asarray(scan.ranges, dtype=float)[valid]
    a = beam_angles(scan, mount)[valid] + th
    c, s = math.cos(th), math.sin(th)
    ox, oy = x + c * mount[0] - s * mount[1], y + s * mount[0] + c * mount[1]
    return np.array([ox, oy]), np.stack([ox + r * np.cos(a), oy + r * np.sin(a)], axis=1)


def _cells_of_beams(origin, ends, lo, res: float, rows: int, cols: int):
    """Flat indices of the cells the beams from ``origin`` pass (before their end cell)
    and of their end cells, each once."""
    if len(ends) == 0:
        z = np.zeros(0, dtype=np.int64)
        return z, z
    d = ends - origin
    length = np.hypot(d[:, 0], d[:, 1])
    step = STEP_SHARE * res
    n = np.ceil(length / step).astype(np.int64)
    beam = np.repeat(np.arange(len(ends)), n)
    k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    t = (k * step) / np.maximum(length[beam], 1e-12)
    xy = origin + t[:, None] * d[beam]
    return _flat(xy, lo, res, rows, cols), _flat(ends, lo, res, rows, cols)


def _flat(xy: np.ndarray, lo, res: float, rows: int, cols: int) -> np.ndarray:
    c = np.floor((xy[:, 0] - lo[0]) / res).astype(np.int64)
    r = np.floor((xy[:, 1] - lo[1]) / res).astype(np.int64)
    ok = (c >= 0) & (c < cols) & (r >= 0) & (r < rows)
    return np.unique(r[ok] * cols + c[ok])
