"""How well a PolyMap built from real scans agrees with the log-odds grid of the same scans
at the same poses (``polyswarm.grids.logodds``): the scores of ``polyswarm bench maps``.

* ``wall_recall``: the share of the grid's occupied cells within ``TOLERANCE_M`` of an
  obstacle vector;
* ``walls_as_frontier``: the share of them within it of a frontier vector but of no
  obstacle vector (a wall the map left open);
* ``explored_unseen_share``: the share of the explored area farther than ``TOLERANCE_M``
  from every cell a beam with a return crossed or hit, or outside the grid (free space
  nobody saw);
* ``explored_over_free``: explored area over the grid's free area.

    scores = score_against_grid(pmap, grid)
"""

from __future__ import annotations

import numpy as np
import shapely
from scipy import ndimage

from polyswarm.grids.logodds import LogOddsGrid
from polyswarm.polymap import GridPolyMap, VectorType

TOLERANCE_M = 0.10  # a wall this close to an obstacle vector is mapped; the figure


def _near(points: np.ndarray, starts: np.ndarray, ends: np.ndarray, tol: float) -> np.ndarray:
    """Which points lie within ``tol`` of one of the segments."""
    out = np.zeros(len(points), dtype=bool)
    if len(points) == 0 or len(starts) == 0:
        return out
    tree = shapely.STRtree(shapely.linestrings(np.stack([starts, ends], axis=1)))
    hit, _ = tree.query(shapely.points(points), predicate="dwithin", distance=tol)
    out[np.unique(hit)] = True
    return out


def explored_mask(pmap: GridPolyMap, grid: LogOddsGrid) -> np.ndarray:
    """The grid's cells whose centres lie in the map's explored space."""
    rows, cols = grid.log_odds.shape
    x = grid.origin[0] + (np.arange(cols) + 0.5) * grid.resolution
    y = grid.origin[1] + (np.arange(rows) + 0.5) * grid.resolution
    xx, yy = np.meshgrid(x, y)
    out = np.zeros((rows, cols), dtype=bool)
    for cell in pmap.cells.values():
        if not cell.polygons:
            continue
        x0, y0, x1, y1 = cell.region.bounds
        c0, c1 = np.searchsorted(x, [x0, x1])
        r0, r1 = np.searchsorted(y, [y0, y1])
        if c0 >= c1 or r0 >= r1:
            continue
        sub = shapely.contains_xy(cell.region, xx[r0:r1, c0:c1], yy[r0:r1, c0:c1])
        out[r0:r1, c0:c1] |= sub
    return out


def score_against_grid(
    pmap: GridPolyMap, grid: LogOddsGrid, tolerance_m: float = TOLERANCE_M
) -> dict[str, float]:
    """The four scores of the module docstring, and the areas behind them."""
    walls = grid.centres(grid.occupied)
    os_, oe, _ = pmap.vectors([VectorType.OBSTACLE])
    fs, fe, _ = pmap.vectors([VectorType.FRONTIER])
    on_obstacle = _near(walls, os_, oe, tolerance_m)
    on_frontier = _near(walls, fs, fe, tolerance_m) & ~on_obstacle
    n = max(len(walls), 1)
    explored = explored_mask(pmap, grid)
    cell_area = grid.resolution**2
    # distance of every cell centre to the nearest touched cell's centre, less half a cell
    # (the distance to that cell's square, near enough on a 5 cm grid)
    dist = ndimage.distance_transform_edt(~grid.touched) * grid.resolution
    unseen = explored & (dist - 0.5 * grid.resolution > tolerance_m)
    explored_m2 = pmap.explored_area()
    rows, cols = grid.log_odds.shape
    x0, y0 = grid.origin
    inside = shapely.box(x0, y0, x0 + cols * grid.resolution, y0 + rows * grid.resolution)
    outside_m2 = float(shapely.difference(pmap.explored_region(), inside).area)
    free_m2 = float(grid.free.sum()) * cell_area
    return {
        "grid_wall_cells": len(walls),
        "wall_recall": float(on_obstacle.sum() / n),
        "walls_as_frontier": float(on_frontier.sum() / n),
        "explored_m2": explored_m2,
        "grid_free_m2": free_m2,
        "explored_unseen_m2": float(unseen.sum()) * cell_area + outside_m2,
        "explored_unseen_share": (float(unseen.sum()) * cell_area + outside_m2)
        / max(explored_m2, cell_area),
        "explored_over_free": explored_m2 / free_m2 if free_m2 > 0 else float("nan"),
    }
