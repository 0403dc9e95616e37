"""Where robots start: beside each other at the world's start (``spread_start_poses``) or
scattered over the world, seeded (``scattered_start_poses``, for unknown starts)."""

from __future__ import annotations

import math

import numpy as np
import shapely

from polyswarm.errors import SimulationError
from sim.shapes import World

SPAWN_CLEARANCE_M = 0.15  # free space kept around a robot placed automatically


def spread_start_poses(
    world: World, n: int, radius: float, spacing: float = 1.0
) -> list[tuple[float, float, float]]:
    """N robots 1 m apart along x from the world's start, each with clearance."""
    safe = world.free.buffer(-(radius + SPAWN_CLEARANCE_M))
    if safe.is_empty:
        raise SimulationError(f"world {world.name!r} has no room for a robot of radius {radius} m")
    shapely.prepare(safe)
    sx, sy = world.start
    poses: list[tuple[float, float, float]] = []
    cands = [(sx + k * spacing, sy) for k in range(4 * n)]
    # then a spiral around the start for crowded starts
    cands += [
        (sx + rr * math.cos(a), sy + rr * math.sin(a))
        for rr in np.arange(0.5, 10.0, 0.5)
        for a in np.linspace(
            0, 2 * math.pi, max(8, int(2 * math.pi * rr / spacing)), endpoint=False
        )
    ]
    for x, y in cands:
        if len(poses) == n:
            break
        if not safe.contains(shapely.Point(x, y)):
            continue
        if all(
            math.hypot(x - px, y - py) >= 2 * radius + 2 * SPAWN_CLEARANCE_M for px, py, _ in poses
        ):
            poses.append((float(x), float(y), world.start_heading))
    if len(poses) < n:
        raise SimulationError(f"could not place {n} robots near the start of {world.name!r}")
    return poses


SCATTER_SEPARATION_M = 10.0  # robots placed "anywhere" start at least this far apart...
SCATTER_CANDIDATES = 4000  # ...out of this many random free spots (fewer apart if need be)


def scattered_start_poses(
    world: World, n: int, radius: float, seed: int, min_separation_m: float = SCATTER_SEPARATION_M
) -> list[tuple[float, float, float]]:
    """N robots at random free poses with random headings, seeded: the start poses nobody
    measured. Each is at least ``min_separation_m`` from the others where the world
    allows; where it does not, the separation is halved until they fit."""
    safe = world.free.buffer(-(radius + SPAWN_CLEARANCE_M))
    if safe.is_empty:
        raise SimulationError(f"world {world.name!r} has no room for a robot of radius {radius} m")
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = safe.bounds
    xy = rng.uniform((x0, y0), (x1, y1), size=(SCATTER_CANDIDATES, 2))
    xy = xy[shapely.contains_xy(safe, xy[:, 0], xy[:, 1])]
    heading = rng.uniform(-math.pi, math.pi, size=len(xy))
    sep = min_separation_m
    while sep >= 2 * radius + 2 * SPAWN_CLEARANCE_M:
        chosen: list[int] = []
        for k in range(len(xy)):  # first fit in the random order
            if all(np.hypot(*(xy[k] - xy[c])) >= sep for c in chosen):
                chosen.append(k)
                if len(chosen) == n:
                    return [(float(xy[k][0]), float(xy[k][1]), float(heading[k])) for k in chosen]
        sep /= 2
    raise SimulationError(f"could not place {n} robots apart in {world.name!r}")
