"""What every world is made of: the ``World`` record and walls built from lines.

walls = walls_from_lines([square(0, 0, 10, 6), [(4, 0), (4, 2)]])
world = world_from_walls("flat", walls, start=(1.5, 1.5))
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
import shapely.ops
from shapely.geometry import LineString, Point, box

from polyswarm.errors import SimulationError
from polyswarm.grids.occupancy import OccupancyGrid

WALL_THICKNESS_M = 0.2  # procedural walls: as thick as one pixel of the thesis maps
WALL_HEIGHT_M = 1.0  # above every lidar mount


@dataclass(frozen=True, eq=False)
class World:
    name: str
    walls: shapely.Geometry  # solid material, (Multi)Polygon
    free: shapely.Geometry  # ground truth: free space reachable from the start area
    start: tuple[float, float]  # centre of the start area
    start_heading: float = 0.0
    boxes: np.ndarray | None = None  # (k, 4) x0 y0 x1 y1 of wall boxes (grid worlds)
    grid: OccupancyGrid | None = None

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        return tuple(shapely.bounds(shapely.union(self.walls, self.free)))  # type: ignore[return-value]

    @property
    def wall_segments(self) -> tuple[np.ndarray, np.ndarray]:
        """Outline of the walls as segments (starts, ends)."""
        rings = shapely.get_rings(shapely.get_parts(self.walls))
        starts, ends = [], []
        for r in rings:
            c = shapely.get_coordinates(r)
            starts.append(c[:-1])
            ends.append(c[1:])
        return np.concatenate(starts), np.concatenate(ends)

    @property
    def free_area(self) -> float:
        return float(self.free.area)


def walls_from_lines(lines: list, thickness: float = WALL_THICKNESS_M) -> shapely.Geometry:
    geoms = [
        LineString(ln).buffer(thickness / 2, cap_style="square", join_style="mitre") for ln in lines
    ]
    return shapely.union_all(geoms, grid_size=1e-6)


def world_from_walls(
    name: str, walls: shapely.Geometry, start: tuple[float, float], heading: float = 0.0
) -> World:
    x0, y0, x1, y1 = walls.bounds
    space = box(x0 - 1, y0 - 1, x1 + 1, y1 + 1).difference(walls)
    parts = [p for p in shapely.get_parts(space) if p.contains(Point(start))]
    if not parts:
        raise SimulationError(f"start {start} of world {name!r} is inside a wall")
    free = parts[0]
    if free.bounds[0] < x0:
        raise SimulationError(f"world {name!r} is not closed around its start")
    return World(name, walls, free, start, heading)


def square(x0, y0, x1, y1):
    return [(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)]


DARK_STRETCH_M = (0.5, 2.0)  # a glass door, a black cabinet: how long a dark stretch is
DARK_DEPTH_M = 0.05  # a hit this close to a dark stretch is on it


def dark_surfaces(world: World, share: float, seed: int) -> shapely.Geometry:
    """Stretches of the walls' outline, about ``share`` of its length in pieces of 0.5-2 m
    (seeded), that are glass or black: a thin band along them (empty for share 0)."""
    if share <= 0:
        return shapely.Polygon()
    rng = np.random.default_rng([seed, 7])
    pieces = []
    for ring in shapely.get_rings(shapely.get_parts(world.walls)):
        length, at = ring.length, 0.0
        while at < length:
            step = float(rng.uniform(*DARK_STRETCH_M))
            if rng.random() < share:
                pieces.append(shapely.ops.substring(ring, at, min(at + step, length)))
            at += step
    if not pieces:
        return shapely.Polygon()
    return shapely.union_all(shapely.buffer(np.array(pieces, dtype=object), DARK_DEPTH_M))
