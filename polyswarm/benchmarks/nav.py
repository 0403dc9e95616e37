"""``polyswarm bench nav``: PolyMap navigation against 8-connected A* on the grid."""

from __future__ import annotations

import time

import numpy as np
from scipy import ndimage

from polyswarm.config import Config
from polyswarm.convert import grid_to_polymap, polymap_to_grid
from polyswarm.data import WORLDS, world_yaml
from polyswarm.errors import PlanningError
from polyswarm.gridplan import cells_to_points, grid_astar, inflated
from polyswarm.io.mapserver import read_map
from polyswarm.navgraph import NavGraph
from polyswarm.planner import Planner, path_clearance

GRID_M = 0.05  # the thesis compares on a 5 cm grid


def compare(pmap, grid, walls, radius: float, robot_radius: float, pairs: int, seed: int) -> dict:
    t0 = time.perf_counter()
    graph = NavGraph.build(pmap, radius)
    build_s = time.perf_counter() - t0
    trav = inflated(grid, radius)
    labels, _ = ndimage.label(trav, ndimage.generate_binary_structure(2, 2))
    main = np.argmax(np.bincount(labels.ravel())[1:]) + 1
    cells = np.argwhere(labels == main)
    rng = np.random.default_rng(seed)
    planner = Planner(pmap, graph)
    rows, failures = [], 0
    violations = 0
    ws, we = walls
    while len(rows) < pairs and failures < 5 * pairs:
        a, b = cells[rng.integers(len(cells), size=2)]
        pa, pb = cells_to_points(grid, [a, b])
        if np.hypot(*(pa - pb)) < 5.0:
            continue
        t0 = time.perf_counter()
        try:
            path = planner.plan(pa, pb)
        except PlanningError:
            failures += 1
            continue
        ours_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        gpath, _ = grid_astar(trav, tuple(a), tuple(b))
        grid_s = time.perf_counter() - t0
        if gpath is None:
            failures += 1
            continue
        gpts = cells_to_points(grid, gpath)
        glen = float(np.hypot(*np.diff(gpts, axis=0).T).sum())
        clear = path_clearance(path.points, ws, we)
        violations += clear < robot_radius - 1e-9
        rows.append((path.length_m, glen, ours_s, grid_s, clear))
    r = np.array(rows)
    return {
        "nodes": graph.node_count,
        "pieces": graph.piece_count,
        "edges": graph.edge_count,
        "graph_build_s": build_s,
        "inflated_grid_free_cells": int(trav.sum()),
        "node_ratio": float(trav.sum() / max(graph.node_count, 1)),
        "pairs": len(r),
        "planner_failures": failures,
        "path_length_ratio_median": float(np.median(r[:, 0] / r[:, 1])),
        "path_length_ratio_p90": float(np.percentile(r[:, 0] / r[:, 1], 90)),
        "planning_ms_median": float(np.median(r[:, 2]) * 1e3),
        "grid_astar_ms_median": float(np.median(r[:, 3]) * 1e3),
        "planning_speedup_median": float(np.median(r[:, 3] / r[:, 2])),
        "min_clearance_to_walls_m": float(r[:, 4].min()),
        "clearance_violations": int(violations),
    }


def update_times(world: str = "office", seed: int = 0, radius: float = 0.25) -> np.ndarray:
    """Graph update time after every keyframe delta of a simulated PolySLAM run."""
    from polyswarm.runners.slam import run_world
    from polyswarm.slam import PolySlam

    maps = []
    orig = PolySlam.process

    def record(self, scan, odom):
        step = orig(self, scan, odom)
        if step.delta is not None:
            maps.append((self.map, frozenset(c.index for c in step.delta.cells)))
        return step

    PolySlam.process = record
    try:
        run_world(world, Config(), seed)
    finally:
        PolySlam.process = orig
    graph = NavGraph.build(maps[0][0], radius)
    times = []
    for pmap, changed in maps[1:]:
        t0 = time.perf_counter()
        graph.update(pmap, changed)
        times.append(time.perf_counter() - t0)
    return np.array(times) * 1e3


def run(pairs: int = 50, seed: int = 0, progress=None) -> dict:
    cfg = Config()
    radius = cfg.nav.robot_radius_m + cfg.nav.clearance_margin_m
    res: dict = {"planning_radius_m": radius, "robot_radius_m": cfg.nav.robot_radius_m, "maps": {}}
    from sim import load_world

    for w in WORLDS:
        if progress:
            progress(f"world {w}")
        src = read_map(world_yaml(w))
        grid = src.upsample(round(src.resolution / GRID_M))
        pmap = grid_to_polymap(src, cfg.map.cell_size_m)
        walls = load_world(f"data:{w}").wall_segments
        res["maps"][w] = compare(pmap, grid, walls, radius, cfg.nav.robot_radius_m, pairs, seed)
    if progress:
        progress("a PolySLAM map (office)")
    from polyswarm.runners.slam import run_world

    run = run_world("office", cfg, seed)
    grid = polymap_to_grid(run.map, GRID_M, wall_thickness_m=0.1)
    res["maps"]["polyslam_office"] = compare(
        run.map, grid, run.world.wall_segments, radius, cfg.nav.robot_radius_m, pairs, seed
    )
    if progress:
        progress("graph updates along a PolySLAM run")
    up = update_times("office", seed, radius)
    maps = res["maps"].values()
    res.update(
        {
            "node_ratio": float(min(m["node_ratio"] for m in maps)),
            "path_length_ratio_median": float(
                np.median([m["path_length_ratio_median"] for m in maps])
            ),
            "planning_speedup_median": float(
                np.median([m["planning_speedup_median"] for m in maps])
            ),
            "update_p50_ms": float(np.median(up)),
            "update_p95_ms": float(np.percentile(up, 95)),
            "clearance_violations": int(sum(m["clearance_violations"] for m in maps)),
        }
    )
    return res
