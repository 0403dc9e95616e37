"""The occupancy-grid baseline planners (thesis 4.7): 8-connected shortest paths on an
inflated grid.

Used by ``polyswarm bench nav`` to compare against PolyMap navigation. Traversable
cells are free cells at least ``radius`` from every cell that is not free (occupied or
unknown: the robot's disc must fit in explored free space, as on the PolyMap).
``grid_mcp`` is the strong baseline: scikit-image's compiled minimum-cost-path search
(``MCP_Geometric``, Dijkstra in Cython, stopping at the goal). ``grid_astar`` is a
plain, careful Python A* with an octile heuristic (the figure of earlier benches).
"""

from __future__ import annotations

import heapq
import math

import numpy as np
from scipy import ndimage

from polyswarm.grids.occupancy import OccupancyGrid

SQRT2 = math.sqrt(2.0)


def inflated(grid: OccupancyGrid, radius: float) -> np.ndarray:
    """Free cells whose centre is at least ``radius`` from every cell that is not free."""
    dist = ndimage.distance_transform_edt(np.pad(grid.free, 1))[1:-1, 1:-1] * grid.resolution
    # distance between cell centres overstates the distance to an occupied cell's edge
    # by half a cell
    return grid.free & (dist - 0.5 * grid.resolution >= radius)


def grid_astar(trav: np.ndarray, start: tuple[int, int], goal: tuple[int, int]):
    """Cells (row, col) of a shortest 8-connected path and the number of expansions."""
    rows, cols = trav.shape
    if not (trav[start] and trav[goal]):
        return None, 0
    flat = trav.ravel().tolist()
    s, g = start[0] * cols + start[1], goal[0] * cols + goal[1]
    gr, gc = goal
    best = {s: 0.0}
    parent = {}
    closed = bytearray(rows * cols)
    heap = [(0.0, s)]
    steps = (
        (-1, 0, 1.0),
        (1, 0, 1.0),
        (0, -1, 1.0),
        (0, 1, 1.0),
        (-1, -1, SQRT2),
        (-1, 1, SQRT2),
        (1, -1, SQRT2),
        (1, 1, SQRT2),
    )
    exp = 0
    while heap:
        _, n = heapq.heappop(heap)
        if closed[n]:
            continue
        if n == g:
            path = [n]
            while path[-1] != s:
                path.append(parent[path[-1]])
            return [divmod(k, cols) for k in reversed(path)], exp
        closed[n] = 1
        exp += 1
        r, c = divmod(n, cols)
        gn = best[n]
        for dr, dc, w in steps:
            rr, cc = r + dr, c + dc
            if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
                continue
            m = rr * cols + cc
            if not flat[m] or closed[m]:
                continue
            if dr and dc and not (flat[r * cols + cc] and flat[rr * cols + c]):
                continue  # no cutting corners between two blocked cells
            cand = gn + w
            if cand < best.get(m, math.inf):
                best[m] = cand
                parent[m] = n
                dx, dy = abs(rr - gr), abs(cc - gc)
                h = (dx + dy) + (SQRT2 - 2.0) * min(dx, dy)
                heapq.heappush(heap, (cand + h, m))
    return None, exp


def grid_mcp(trav: np.ndarray, start: tuple[int, int], goal: tuple[int, int]):
    """Cells (row, col) of a shortest 8-connected path by scikit-image's compiled
    ``MCP_Geometric`` (diagonal steps cost sqrt 2), or None."""
    from skimage.graph import MCP_Geometric

    if not (trav[start] and trav[goal]):
        return None
    costs = np.where(trav, 1.0, np.inf)
    mcp = MCP_Geometric(costs, fully_connected=True)
    cum, _ = mcp.find_costs([start], [goal])
    if not np.isfinite(cum[goal]):
        return None
    return [tuple(rc) for rc in mcp.traceback(goal)]


def cells_to_points(grid: OccupancyGrid, cells) -> np.ndarray:
    rc = np.asarray(cells, dtype=float)
    x = grid.origin[0] + (rc[:, 1] + 0.5) * grid.resolution
    y = grid.origin[1] + (rc[:, 0] + 0.5) * grid.resolution
    return np.stack([x, y], axis=1)
