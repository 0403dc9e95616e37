"""Worlds: walls, ground-truth free space and start areas.

Two sources:

* ROS map_server maps (``world_from_map_yaml``): occupied pixels become wall boxes,
  neighbouring pixels merged into as few boxes as possible (row runs, then identical
  runs stacked). Unknown pixels that touch the reachable free space are walled too,
  so lidar beams cannot leak out through gaps in the mapped walls, and so is the ring
  just outside the image where free pixels reach its edge (Nav2's warehouse and depot
  maps do): no robot drives off the map.
* procedural worlds defined in code (``procedural_world``): loop, cross, zigzag, maze
  (seeded), office, curves, rooms and furnished (seeded clutter, `sim.furnished`), so
  the simulator works with nothing installed.

Every world knows its ground truth: the free space reachable from the start area and
the wall outlines as segments (for coverage and map-accuracy metrics).
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import shapely
from scipy import ndimage
from shapely.geometry import Point
from shapely.ops import nearest_points

from polyswarm.errors import SimulationError
from polyswarm.grids.occupancy import UNKNOWN, OccupancyGrid
from sim.furnished import furnished_world
from sim.shapes import (
    World,
    square,
    walls_from_lines,
    world_from_walls,
)

PROCEDURAL = ("loop", "cross", "zigzag", "maze", "office", "curves", "rooms", "furnished")


# ---------------------------------------------------------------------------------------
# Worlds from occupancy grids
# ---------------------------------------------------------------------------------------


def merge_boxes(mask: np.ndarray) -> np.ndarray:
    """Cover the True pixels of ``mask`` with few axis-aligned boxes (pixel units).

    Returns (k, 4) arrays of [col0, row0, col1, row1) rectangles: maximal horizontal runs
    per row, then runs with the same columns in consecutive rows stacked into one box.
    """
    rows, _ = mask.shape
    open_runs: dict[tuple[int, int], int] = {}  # (c0, c1) -> first row
    out = []
    for r in range(rows + 1):
        runs = set()
        if r < rows:
            line = np.concatenate([[False], mask[r], [False]])
            d = np.diff(line.astype(np.int8))
            starts, ends = np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]
            runs = set(zip(starts.tolist(), ends.tolist(), strict=True))
        for run in list(open_runs):
            if run not in runs:
                out.append((run[0], open_runs.pop(run), run[1], r))
        for run in runs:
            open_runs.setdefault(run, r)
    return np.array(sorted(out), dtype=np.int64).reshape(-1, 4)


def default_start(free: shapely.Geometry, clearance: float = 0.5) -> tuple[float, float]:
    """About 2 m inside the lower-left corner of the free space (the thesis start)."""
    x0, y0, _, _ = free.bounds
    safe = free.buffer(-clearance)
    target = Point(x0 + 2.0, y0 + 2.0)
    if safe.is_empty:
        raise SimulationError("no free space with enough clearance for a start area")
    if safe.contains(target):
        return (target.x, target.y)
    p = nearest_points(safe, target)[0]
    return (p.x, p.y)


def world_from_grid(
    truth: OccupancyGrid, name: str, start: tuple[float, float] | None = None
) -> World:
    grid = _ringed(truth)
    free_px = grid.free
    labels, n = ndimage.label(free_px)
    if n == 0:
        raise SimulationError(f"world {name!r} has no free space")
    res, (ox, oy) = grid.resolution, grid.origin
    if start is None:
        sizes = np.bincount(labels.ravel())[1:]
        main = int(np.argmax(sizes)) + 1
    else:
        r, c = grid.world_to_cell(*start)
        if not (0 <= r < grid.shape[0] and 0 <= c < grid.shape[1]) or labels[r, c] == 0:
            raise SimulationError(f"start {start} is not in free space of world {name!r}")
        main = int(labels[r, c])
    reach = labels == main
    # wall every occupied pixel, and unknown pixels touching the reachable free space
    touching = ndimage.binary_dilation(reach, ndimage.generate_binary_structure(2, 1))
    solid = grid.occupied | (touching & (grid.data == -1))
    px = merge_boxes(solid)
    boxes = np.stack(
        [ox + px[:, 0] * res, oy + px[:, 1] * res, ox + px[:, 2] * res, oy + px[:, 3] * res], axis=1
    )
    walls = shapely.union_all(shapely.box(*boxes.T), grid_size=1e-6)
    free = _pixels_to_region(reach, grid)
    if start is None:
        start = default_start(free)
    return World(name, walls, free, start, 0.0, boxes, truth)


def _ringed(grid: OccupancyGrid) -> OccupancyGrid:
    """The grid inside a ring of unknown pixels, one pixel wide."""
    res, (ox, oy) = grid.resolution, grid.origin
    data = np.pad(grid.data, 1, constant_values=UNKNOWN)
    return OccupancyGrid(data, res, (ox - res, oy - res))


def _pixels_to_region(mask: np.ndarray, grid: OccupancyGrid) -> shapely.Geometry:
    px = merge_boxes(mask)
    res, (ox, oy) = grid.resolution, grid.origin
    b = shapely.box(
        ox + px[:, 0] * res, oy + px[:, 1] * res, ox + px[:, 2] * res, oy + px[:, 3] * res
    )
    return shapely.union_all(b, grid_size=1e-6)


def world_from_map_yaml(path: str | Path, start: tuple[float, float] | None = None) -> World:
    from polyswarm.io.mapserver import read_map

    p = Path(path)
    return world_from_grid(read_map(p), p.stem, start)


# ---------------------------------------------------------------------------------------
# Procedural worlds
# ---------------------------------------------------------------------------------------


def loop_world(size: float = 40.0, corridor: float = 5.0) -> World:
    """A square corridor around a closed block: loop closure after a long drive."""
    walls = walls_from_lines(
        [square(0, 0, size, size), square(corridor, corridor, size - corridor, size - corridor)]
    )
    return world_from_walls("loop", walls, (2.0, 2.0))


def cross_world(size: float = 40.0, corridor: float = 5.0) -> World:
    """An outer loop plus a cross of corridors through the middle: four blocks."""
    c, h = size / 2, corridor / 2
    blocks = [
        square(corridor, corridor, c - h, c - h),
        square(c + h, corridor, size - corridor, c - h),
        square(corridor, c + h, c - h, size - corridor),
        square(c + h, c + h, size - corridor, size - corridor),
    ]
    walls = walls_from_lines([square(0, 0, size, size), *blocks])
    return world_from_walls("cross", walls, (2.0, 2.0))


def zigzag_world(width: float = 40.0, lanes: int = 4, corridor: float = 4.0) -> World:
    """Parallel corridors joined alternately at the ends: one long path."""
    height = lanes * corridor
    lines = [square(0, 0, width, height)]
    for k in range(1, lanes):
        y = k * corridor
        if k % 2 == 1:
            lines.append([(0, y), (width - corridor, y)])
        else:
            lines.append([(corridor, y), (width, y)])
    return world_from_walls("zigzag", walls_from_lines(lines), (2.0, 2.0))


def maze_world(cells: int = 6, cell: float = 4.0, seed: int = 0) -> World:
    """A perfect maze (randomised depth-first search), seeded."""
    rng = np.random.default_rng(seed)
    # walls between cells: h[i][j] is the wall above cell (i, j); v[i][j] right of it
    h = np.ones((cells, cells), dtype=bool)
    v = np.ones((cells, cells), dtype=bool)
    seen = np.zeros((cells, cells), dtype=bool)
    stack = [(0, 0)]
    seen[0, 0] = True
    while stack:
        i, j = stack[-1]
        nbrs = [
            (i + di, j + dj)
            for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1))
            if 0 <= i + di < cells and 0 <= j + dj < cells and not seen[i + di, j + dj]
        ]
        if not nbrs:
            stack.pop()
            continue
        ni, nj = nbrs[int(rng.integers(len(nbrs)))]
        if ni == i + 1:
            v[i, j] = False
        elif ni == i - 1:
            v[ni, nj] = False
        elif nj == j + 1:
            h[i, j] = False
        else:
            h[ni, nj] = False
        seen[ni, nj] = True
        stack.append((ni, nj))
    size = cells * cell
    lines = [square(0, 0, size, size)]
    for i in range(cells):
        for j in range(cells):
            if h[i, j] and j < cells - 1:
                lines.append([(i * cell, (j + 1) * cell), ((i + 1) * cell, (j + 1) * cell)])
            if v[i, j] and i < cells - 1:
                lines.append([((i + 1) * cell, j * cell), ((i + 1) * cell, (j + 1) * cell)])
    return world_from_walls("maze", walls_from_lines(lines), (cell / 2, cell / 2))


def office_world() -> World:
    """About 20 m x 15 m: a corridor with rooms on both sides, doors 0.9 m wide."""
    W, H = 20.0, 15.0
    cy0, cy1 = 6.0, 8.5  # corridor between y = 6 and y = 8.5
    door = 0.9
    lines = [square(0, 0, W, H)]
    xs = [0.0, 5.0, 10.0, 15.0, W]
    # corridor walls with a door to every room
    for y in (cy0, cy1):
        segs = []
        for a, b in itertools.pairwise(xs):
            mid = (a + b) / 2
            segs.append((a, mid - door / 2))
            segs.append((mid + door / 2, b))
        # join consecutive segments that meet at room dividers
        for a, b in segs:
            lines.append([(a, y), (b, y)])
    for x in xs[1:-1]:
        lines.append([(x, 0.0), (x, cy0)])
        lines.append([(x, cy1), (x, H)])
    # a meeting table in the last room and a pillar in the corridor
    lines.append([(16.5, 11.0), (18.5, 11.0)])
    walls = walls_from_lines(lines)
    walls = shapely.union(walls, Point(12.5, 7.25).buffer(0.25, quad_segs=8))
    return world_from_walls("office", walls, (1.5, 7.25))


def curves_world() -> World:
    """8 m x 8 m: flat walls, a quarter-round corner, a round pillar and an S-curve."""
    arc = [
        (8 - 3 + 3 * math.sin(t), 8 - 3 + 3 * math.cos(t)) for t in np.linspace(0, math.pi / 2, 24)
    ]
    outer = [(0, 0), (8, 0), *arc[::-1], (0, 8), (0, 0)]
    s_curve = [
        (1.5 + 0.4 * math.sin(t), 4.0 + 1.5 * t / math.pi)
        for t in np.linspace(-math.pi, math.pi, 40)
    ]
    walls = walls_from_lines([outer, s_curve], 0.15)
    walls = shapely.union(walls, Point(5.0, 3.0).buffer(0.6, quad_segs=16))
    return world_from_walls("curves", walls, (3.5, 1.2), math.pi / 2)


def rooms_world() -> World:
    """A small 10 m x 6 m flat with three rooms: the quick end-to-end test world."""
    lines = [
        square(0, 0, 10, 6),
        [(4.0, 0.0), (4.0, 2.0)],
        [(4.0, 3.0), (4.0, 6.0)],
        [(4.0, 3.0), (7.0, 3.0)],
        [(8.0, 3.0), (10.0, 3.0)],
    ]
    return world_from_walls("rooms", walls_from_lines(lines), (1.5, 1.5))


def procedural_world(name: str, seed: int = 0) -> World:
    makers = {
        "loop": loop_world,
        "cross": cross_world,
        "zigzag": zigzag_world,
        "maze": lambda: maze_world(seed=seed),
        "office": office_world,
        "curves": curves_world,
        "rooms": rooms_world,
        "furnished": lambda: furnished_world(seed),
    }
    if name not in makers:
        raise SimulationError(
            f"unknown world {name!r}: use one of {', '.join(PROCEDURAL)} or a map .yaml"
        )
    return makers[name]()


def load_world(spec: str | Path, seed: int = 0, start: tuple[float, float] | None = None) -> World:
    """A procedural world by name, or a map_server map by path (``.yaml``)."""
    s = str(spec)
    if s.endswith((".yaml", ".yml")):
        return world_from_map_yaml(s, start)
    if s.startswith("data:"):
        from polyswarm.data import world_yaml

        return world_from_map_yaml(world_yaml(s[5:]), start)
    w = procedural_world(s, seed)
    if start is not None:
        w = World(w.name, w.walls, w.free, start, w.start_heading, w.boxes, w.grid)
    return w
