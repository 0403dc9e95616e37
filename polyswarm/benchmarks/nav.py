"""``polyswarm bench nav``: PolyMap navigation against shortest paths on the grid.

The baseline is scikit-image's compiled minimum-cost-path search on the inflated grid
(``polyswarm.nav.gridplan.grid_mcp``) at 5 cm and at the map's own resolution (0.2 m for
the thesis worlds); the pure-Python A* of earlier benches is still timed beside it."""

from __future__ import annotations

import math
import time

import numpy as np
from scipy import ndimage

from polyswarm.config import Config
from polyswarm.data import WORLDS, world_yaml
from polyswarm.errors import PlanningError
from polyswarm.grids.convert import grid_to_polymap, polymap_to_grid
from polyswarm.io.mapserver import read_map
from polyswarm.nav.gridplan import cells_to_points, grid_astar, grid_mcp, inflated
from polyswarm.nav.navgraph import NavGraph
from polyswarm.nav.planner import Planner, path_clearance

GRID_M = 0.05  # the thesis compares on a 5 cm grid


def _cell_of(grid, p) -> tuple[int, int]:
    return (
        int((p[1] - grid.origin[1]) / grid.resolution),
        int((p[0] - grid.origin[0]) / grid.resolution),
    )


def _length(grid, cells) -> float:
    pts = cells_to_points(grid, cells)
    return float(np.hypot(*np.diff(pts, axis=0).T).sum())


def _compare_summary(r: np.ndarray, graph, build_s: float, trav, native, counts) -> dict:
    """``compare``'s figures from its rows (``r``: our length, the grid A*'s length, our
    and its seconds, clearance, the compiled planner's length and seconds, the same at
    the map's own resolution) and its counts (failures, native failures, violations)."""
    failures, native_failures, violations = counts
    ok_nat = np.isfinite(r[:, 7])
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
        # against the compiled planner, at 5 cm and at the map's own resolution
        "grid_mcp_ms_median": float(np.median(r[:, 6]) * 1e3),
        "speedup_vs_compiled_median": float(np.median(r[:, 6] / r[:, 2])),
        "path_length_ratio_vs_compiled_median": float(np.nanmedian(r[:, 0] / r[:, 5])),
        "native_resolution_m": None if native is None else native.resolution,
        "native_mcp_ms_median": float(np.median(r[ok_nat, 8]) * 1e3) if ok_nat.any() else None,
        "speedup_vs_native_compiled_median": (
            float(np.median(r[ok_nat, 8] / r[ok_nat, 2])) if ok_nat.any() else None
        ),
        "path_length_ratio_vs_native_median": (
            float(np.median(r[ok_nat, 0] / r[ok_nat, 7])) if ok_nat.any() else None
        ),
        "native_no_path": int(native_failures),
        "min_clearance_to_walls_m": float(r[:, 4].min()),
        "clearance_violations": int(violations),
    }


def compare(
    pmap, grid, walls, radius: float, robot_radius: float, pairs: int, seed: int, native=None
) -> dict:
    """``native``: the map's own grid (coarser), planned on as well."""
    t0 = time.perf_counter()
    graph = NavGraph.build(pmap, radius)
    build_s = time.perf_counter() - t0
    trav = inflated(grid, radius)
    trav_native = None if native is None else inflated(native, radius)
    labels, _ = ndimage.label(trav, ndimage.generate_binary_structure(2, 2))
    main = np.argmax(np.bincount(labels.ravel())[1:]) + 1
    cells = np.argwhere(labels == main)
    rng = np.random.default_rng(seed)
    planner = Planner(pmap, graph)
    rows, failures, native_failures = [], 0, 0
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
        glen = _length(grid, gpath)
        t0 = time.perf_counter()
        mpath = grid_mcp(trav, tuple(a), tuple(b))
        mcp_s = time.perf_counter() - t0
        mlen = math.nan if mpath is None else _length(grid, mpath)
        nat_s = nat_len = math.nan
        if trav_native is not None:
            na, nb = _cell_of(native, pa), _cell_of(native, pb)
            t0 = time.perf_counter()
            npath = grid_mcp(trav_native, na, nb)
            nat_s = time.perf_counter() - t0
            nat_len = math.nan if npath is None else _length(native, npath)
            native_failures += npath is None
        clear = path_clearance(path.points, ws, we)
        violations += clear < robot_radius - 1e-9
        rows.append((path.length_m, glen, ours_s, grid_s, clear, mlen, mcp_s, nat_len, nat_s))
    counts = (failures, native_failures, violations)
    return _compare_summary(np.array(rows), graph, build_s, trav, native, counts)


def update_times(world: str = "office", seed: int = 0, radius: float = 0.25) -> np.ndarray:
    """Graph update time after every keyframe delta of a simulated PolySLAM run."""
    from polyswarm.runners.slam import run_world
    from polyswarm.slam.polyslam import PolySlam

    maps = []
    orig = PolySlam.process

    def record(self, scan, odom, motion=None):
        step = orig(self, scan, odom, motion)
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
        res["maps"][w] = compare(
            pmap, grid, walls, radius, cfg.nav.robot_radius_m, pairs, seed, native=src
        )
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
            "speedup_vs_compiled_median": float(
                np.median([m["speedup_vs_compiled_median"] for m in maps])
            ),
            "update_p50_ms": float(np.median(up)),
            "update_p95_ms": float(np.percentile(up, 95)),
            "clearance_violations": int(sum(m["clearance_violations"] for m in maps)),
        }
    )
    return res
