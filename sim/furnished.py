"""``furnished``: a seeded office floor with the clutter real buildings have.

24 m x 16 m: a corridor along the middle with pillars; four offices to the south, an
open-plan office and two meeting rooms to the north, doors 0.9 m wide. The rooms are
furnished as a 2D lidar at about 0.2 m above the floor sees them:

* desks as their four legs (5 cm square; a robot of 0.4 m height passes below the top),
* office chairs as their gas column (6 cm round), four-legged chairs as four legs,
* shelves and cabinets as solid boxes (a plinth down to the floor),
* pillars (0.4 m square) in the corridor and the open-plan office,
* rows of desks with passages of 0.7-1.0 m between them in the open-plan office.

Legs and columns cast thin shadows and let beams through between them: the frontier
slivers and narrow passages a furnished building makes. A clear area is kept inside
every door, so every room can be entered; what lies behind furniture may not be
reachable for a robot's footprint, which the coverage measure takes into account.

    world = furnished_world(seed=3)
"""

from __future__ import annotations

import itertools

import numpy as np
import shapely
from shapely.geometry import Point, box

from sim.shapes import World, square, walls_from_lines, world_from_walls

WIDTH_M, HEIGHT_M = 24.0, 16.0
CORRIDOR_Y = (6.5, 9.0)  # the corridor between these walls
DOOR_M = 0.9
DOOR_CLEAR_M = 1.2  # nothing placed within this of a door's middle
LEG_M = 0.05  # desk and table legs, square
COLUMN_RADIUS_M = 0.03  # an office chair's gas column
WALL_GAP_M = 0.05  # furniture "against a wall" stands this far from it


def _legs(x0: float, y0: float, x1: float, y1: float) -> list:
    """Four square legs at the corners of a table top (x0, y0)-(x1, y1)."""
    h = LEG_M / 2
    return [box(x - h, y - h, x + h, y + h) for x in (x0 + h, x1 - h) for y in (y0 + h, y1 - h)]


class _Room:
    """Places furniture in a rectangle, keeping doors clear and pieces apart."""

    def __init__(self, rng, x0, y0, x1, y1, doors) -> None:
        self.rng, self.bounds = rng, (x0, y0, x1, y1)
        self.keep_clear = [Point(d).buffer(DOOR_CLEAR_M) for d in doors]
        self.taken: list = []  # footprints placed so far (with their clearance)
        self.parts: list = []  # the solid geometry

    def place(self, footprint, solid, gap: float = 0.6) -> bool:
        """Add ``solid`` if ``footprint`` lies inside the room, clear of doors and of the
        footprints placed so far by ``gap`` metres (a passage a robot fits through)."""
        x0, y0, x1, y1 = self.bounds
        inside = box(x0 + WALL_GAP_M, y0 + WALL_GAP_M, x1 - WALL_GAP_M, y1 - WALL_GAP_M)
        if not inside.contains(footprint) or any(footprint.intersects(k) for k in self.keep_clear):
            return False
        if any(footprint.distance(t) < gap for t in self.taken):
            return False
        self.taken.append(footprint)
        self.parts.extend(solid if isinstance(solid, list) else [solid])
        return True

    def desk(self, tries: int = 30) -> None:
        """A desk (1.4 x 0.7 m, legs only) with a chair in front of it."""
        x0, y0, x1, y1 = self.bounds
        for _ in range(tries):
            w, d = (1.4, 0.7) if self.rng.random() < 0.5 else (0.7, 1.4)
            x = self.rng.uniform(x0, x1 - w)
            y = self.rng.uniform(y0, y1 - d)
            top = box(x, y, x + w, y + d)
            # the chair beside the long side, inside the room
            if w > d:
                cy = y - 0.35 if self.rng.random() < 0.5 else y + d + 0.35
                chair = Point(x + w / 2, cy)
            else:
                cx = x - 0.35 if self.rng.random() < 0.5 else x + w + 0.35
                chair = Point(cx, y + d / 2)
            parts = [*_legs(x, y, x + w, y + d), chair.buffer(COLUMN_RADIUS_M, quad_segs=4)]
            if self.place(shapely.union(top, chair.buffer(0.3)), parts, gap=0.5):
                return

    def against_wall(self, depth: float, length: float, tries: int = 30) -> None:
        """A shelf or cabinet (a solid box) against one of the room's walls."""
        x0, y0, x1, y1 = self.bounds
        g = WALL_GAP_M + 0.01
        for _ in range(tries):
            side = int(self.rng.integers(4))
            if side in (0, 1):  # south or north wall
                x = self.rng.uniform(x0 + g, x1 - g - length)
                y = y0 + g if side == 0 else y1 - g - depth
                b = box(x, y, x + length, y + depth)
            else:  # west or east wall
                y = self.rng.uniform(y0 + g, y1 - g - length)
                x = x0 + g if side == 2 else x1 - g - depth
                b = box(x, y, x + depth, y + length)
            if self.place(b, b, gap=0.6):
                return

    def table(self, tries: int = 30) -> None:
        """A meeting table (legs only) with four-legged chairs around it."""
        x0, y0, x1, y1 = self.bounds
        for _ in range(tries):
            w, d = self.rng.uniform(1.6, 2.4), self.rng.uniform(0.9, 1.2)
            x = self.rng.uniform(x0 + 0.8, x1 - w - 0.8)
            y = self.rng.uniform(y0 + 0.8, y1 - d - 0.8)
            parts = _legs(x, y, x + w, y + d)
            for k in range(3):
                cx = x + (k + 0.5) * w / 3
                for cy in (y - 0.4, y + d + 0.4):
                    parts += _legs(cx - 0.2, cy - 0.2, cx + 0.2, cy + 0.2)
            if self.place(box(x, y - 0.6, x + w, y + d + 0.6), parts, gap=0.6):
                return

    def pillar(self, tries: int = 30) -> None:
        x0, y0, x1, y1 = self.bounds
        for _ in range(tries):
            x, y = self.rng.uniform(x0 + 1, x1 - 1.4), self.rng.uniform(y0 + 1, y1 - 1.4)
            b = box(x, y, x + 0.4, y + 0.4)
            if self.place(b, b, gap=0.8):
                return


def _doors_and_walls(xs: list[float], y: float, doors: list[float]) -> list:
    """A wall along y from xs[0] to xs[-1] with a door centred at each x in ``doors``."""
    cuts = sorted(doors)
    out, x = [], xs[0]
    for d in cuts:
        out.append([(x, y), (d - DOOR_M / 2, y)])
        x = d + DOOR_M / 2
    out.append([(x, y), (xs[-1], y)])
    return out


def furnished_world(seed: int = 0) -> World:
    rng = np.random.default_rng([seed, 7])
    W, H = WIDTH_M, HEIGHT_M
    c0, c1 = CORRIDOR_Y
    south = [0.0, 6.0, 12.0, 18.0, W]  # four offices
    north = [0.0, 14.0, 19.0, W]  # open plan, two meeting rooms
    south_doors = [
        a + 1.5 if k % 2 else b - 1.5 for k, (a, b) in enumerate(itertools.pairwise(south))
    ]
    north_doors = [3.0, 10.0, 16.5, 21.5]
    lines = [square(0, 0, W, H)]
    lines += _doors_and_walls([0.0, W], c0, south_doors)
    lines += _doors_and_walls([0.0, W], c1, north_doors)
    lines += [[(x, 0.0), (x, c0)] for x in south[1:-1]]
    lines += [[(x, c1), (x, H)] for x in north[1:-1]]
    walls = walls_from_lines(lines)
    half = 0.1  # half the walls' thickness
    parts = []
    # the corridor: pillars, and nothing else (it is the way everywhere)
    for x in (5.0, 11.0, 17.0):
        py = c0 + half + 0.05 if rng.random() < 0.5 else c1 - half - 0.45
        parts.append(box(x, py, x + 0.4, py + 0.4))
    # offices: desks, a shelf, a cabinet
    for k, (a, b) in enumerate(itertools.pairwise(south)):
        room = _Room(rng, a + half, half, b - half, c0 - half, [(south_doors[k], c0)])
        for _ in range(int(rng.integers(1, 3))):
            room.desk()
        room.against_wall(0.4, float(rng.uniform(1.0, 2.0)))
        room.against_wall(0.5, 0.8)
        parts += room.parts
    # open plan: two rows of desks back to back, shelves, a pillar
    doors = [(d, c1) for d in north_doors[:2]]
    room = _Room(rng, half, c1 + half, 14.0 - half, H - half, doors)
    room.pillar()
    for _ in range(7):
        room.desk()
    room.against_wall(0.4, 2.0)
    room.against_wall(0.4, 1.5)
    parts += room.parts
    # meeting rooms: a table with chairs, a cabinet
    for k, (a, b) in enumerate(itertools.pairwise(north[1:])):
        room = _Room(rng, a + half, c1 + half, b - half, H - half, [(north_doors[2 + k], c1)])
        room.table()
        room.against_wall(0.5, 1.0)
        parts += room.parts
    walls = shapely.union_all([walls, *parts], grid_size=1e-6)
    return world_from_walls("furnished", walls, (1.0, (c0 + c1) / 2))
