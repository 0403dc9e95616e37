"""``polyswarm bench format``: PolyMap size against PNG, and merge latency."""

from __future__ import annotations

import time
import zlib
from collections.abc import Callable

import numpy as np
import shapely

from polyswarm.config import Config
from polyswarm.data import WORLDS, world_yaml
from polyswarm.grids.convert import grid_to_polymap, polymap_to_grid, round_trip_retention
from polyswarm.grids.counting import CountingGrid
from polyswarm.grids.occupancy import OccupancyGrid
from polyswarm.io.mapserver import grid_png_bytes, read_map
from polyswarm.polymap import GridPolyMap, VectorType
from polyswarm.raycast import cast_rays
from polyswarm.slam.keyframe import keyframe_polygon
from polyswarm.slam.refine import refine_polygon
from polyswarm.slam.scan import LaserScan, scan_to_points
from protocols.mapcodec import encode_map

GRID_RESOLUTION_M = 0.05  # the thesis compares maps on a 5 cm grid (chapter 5.4)
SOURCE_WALL_THICKNESS_M = 0.3  # the data's walls are 1-3 pixels of 0.2 m
ROUTE_KEYFRAMES = 300  # noisy scans along a random walk, for the grid built from scans


def world_sizes(name: str, cell_size: float) -> dict:
    src = read_map(world_yaml(name))
    grid = src.upsample(round(src.resolution / GRID_RESOLUTION_M))
    pmap = grid_to_polymap(grid, cell_size)
    enc = encode_map(pmap)
    polys = pmap.dissolve()
    vectors = sum(len(r) for p in polys for r in p.rings())
    back = polymap_to_grid(
        pmap, grid.resolution, like=grid, wall_thickness_m=SOURCE_WALL_THICKNESS_M
    )
    free_kept, occ_kept = round_trip_retention(grid, back)
    (x0, y0), (rows, cols) = src.origin, src.data.shape
    bounds = (x0, y0, x0 + cols * src.resolution, y0 + rows * src.resolution)
    route_map, route_grid = route_maps(grid_to_polymap(src, cell_size), bounds)
    route_enc = encode_map(route_map, Config().map.whole_map_precision_m)  # as shared
    route_png = len(grid_png_bytes(OccupancyGrid(route_grid.trinary(), GRID_RESOLUTION_M)))
    return {
        "vectors": vectors,
        "polygons": len(polys),
        "encoded_bytes": len(enc),
        "encoded_zlib_bytes": len(zlib.compress(enc, 9)),
        "grid_png_bytes": len(grid_png_bytes(grid)),
        "bytes_ratio_vs_png": len(enc) / len(grid_png_bytes(grid)),
        # the same map as a PNG at its own resolution (0.2 m for the thesis worlds)
        "native_resolution_m": src.resolution,
        "native_png_bytes": len(grid_png_bytes(src)),
        "bytes_ratio_vs_native_png": len(enc) / len(grid_png_bytes(src)),
        # a map built from noisy scans along a route: PolyMap against the 5 cm grid's PNG
        "route_keyframes": ROUTE_KEYFRAMES,
        "route_polymap_bytes": len(route_enc),
        "route_grid_png_bytes": route_png,
        "route_bytes_ratio_vs_png": len(route_enc) / route_png,
        "grid_zlib_bytes": len(zlib.compress(grid.data.tobytes(), 9)),
        "round_trip_free_kept": free_kept,
        "round_trip_occupied_kept": occ_kept,
        "grid_cells": int(grid.data.size),
    }


def _walk(walls: GridPolyMap, rng: np.random.Generator, step_m: float = 0.4):
    """Poses (x, y, theta) of a random walk in steps of ``step_m`` through ``walls``'
    free space, at least 0.4 m from its edges."""
    free = walls.explored_region()
    safe = free.buffer(-0.4)
    shapely.prepare(safe)
    pts = shapely.get_coordinates(safe.representative_point())[0]
    x, y, th = float(pts[0]), float(pts[1]), 0.0
    while True:
        for _ in range(20):
            nth = th + rng.normal(0, 0.5)
            nx, ny = x + step_m * np.cos(nth), y + step_m * np.sin(nth)
            if safe.covers(shapely.LineString([(x, y), (nx, ny)])):
                x, y, th = nx, ny, nth
                break
        else:
            th += np.pi  # dead end: turn around
        yield x, y, th


LIDAR_ANGLES = np.linspace(-3 * np.pi / 4, 3 * np.pi / 4, 720)  # 270 degrees, 720 beams


def keyframe_stream(walls: GridPolyMap, n: int, seed: int = 0, step_m: float = 0.4):
    """Keyframes of 50-150 vectors along a random walk through ``walls``' free space.

    A 270 degree, 720 beam, 30 m lidar (sigma 0.01 m) is cast against the map's obstacle
    vectors, and every k-th beam kept (k in 5..14) so keyframes have 50-150 vectors.
    """
    rng = np.random.default_rng(seed)
    s, e, _ = walls.vectors([VectorType.OBSTACLE])
    angles = LIDAR_ANGLES
    for made, (x, y, th) in enumerate(_walk(walls, rng, step_m)):
        if made >= n:
            return
        r = cast_rays((x, y), angles + th, s, e, 30.0)
        r = r + rng.normal(0, 0.01, len(r))
        k = int(rng.integers(5, 15))
        scan = LaserScan(r[::k], -3 * np.pi / 4, (angles[1] - angles[0]) * k, 0.05, 30.0)
        yield keyframe_polygon(scan_to_points(scan), (x, y, th), max_gap_m=0.5 * k)


def route_maps(walls: GridPolyMap, bounds, n: int = ROUTE_KEYFRAMES, seed: int = 0):
    """The PolyMap and the 5 cm occupancy grid (gmapping's rule) of the same ``n`` noisy
    scans (all 720 beams, sigma 0.01 m) along a random walk, each at its true pose; the
    keyframe polygons refined as PolySLAM refines them (default config)."""
    refine = Config().slam.refine
    rng = np.random.default_rng(seed)
    s, e, _ = walls.vectors([VectorType.OBSTACLE])
    pmap = GridPolyMap(walls.cell_size)
    grid = CountingGrid(bounds, GRID_RESOLUTION_M, free_range_m=30.0)
    inc = LIDAR_ANGLES[1] - LIDAR_ANGLES[0]
    for made, (x, y, th) in enumerate(_walk(walls, rng)):
        if made >= n:
            break
        r = cast_rays((x, y), LIDAR_ANGLES + th, s, e, 30.0)
        r = r + rng.normal(0, 0.01, len(r))
        scan = LaserScan(r, float(LIDAR_ANGLES[0]), float(inc), 0.05, 30.0)
        kf, _ = refine_polygon(keyframe_polygon(scan_to_points(scan), (x, y, th)), refine)
        pmap = pmap.merge(kf).map
        grid.integrate(scan, (x, y, th))
    return pmap, grid


def merge_latency(
    cell_size: float,
    world: str = "maze",
    min_keyframes: int = 400,
    min_map_vectors: int = 5000,
    max_keyframes: int = 6000,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
) -> dict:
    """Merge keyframes until the map holds more than ``min_map_vectors`` vectors."""
    src = read_map(world_yaml(world))
    walls = grid_to_polymap(src, cell_size)
    pmap = GridPolyMap(cell_size)
    times, sizes = [], []
    for k, kf in enumerate(keyframe_stream(walls, max_keyframes, seed)):
        t0 = time.perf_counter()
        pmap = pmap.merge(kf).map
        times.append(time.perf_counter() - t0)
        sizes.append(len(kf.shell))
        if progress:
            progress(k)
        if k + 1 >= min_keyframes and sum(pmap.vector_counts().values()) > min_map_vectors:
            break
    ms = np.array(times) * 1e3
    return {
        "merge_p50_ms": float(np.median(ms)),
        "merge_p95_ms": float(np.percentile(ms, 95)),
        "keyframes": len(ms),
        "keyframe_vectors_min": int(min(sizes)),
        "keyframe_vectors_max": int(max(sizes)),
        "final_map_vectors": int(sum(pmap.vector_counts().values())),
    }


def run(cell_size: float = 2.0, progress=None) -> dict:
    worlds = {}
    for name in WORLDS:
        worlds[name] = world_sizes(name, cell_size)
        if progress:
            progress(name)
    merge = merge_latency(cell_size)
    total_bytes = sum(w["encoded_bytes"] for w in worlds.values())
    total_vectors = sum(w["vectors"] for w in worlds.values())
    return {
        "cell_size_m": cell_size,
        "grid_resolution_m": GRID_RESOLUTION_M,
        "worlds": worlds,
        **merge,
        "bytes_per_vector": total_bytes / max(total_vectors, 1),
    }
