"""``polyswarm bench explore``: whole explorations, and the coordinator under 10 robots.

1. Explorations: ``polyswarm launch`` (every part its own process, Zenoh on loopback)
   per world x robot count x strategy x seed; t99 (simulated seconds to 99% of the
   reachable free space), success, collisions, crashed processes and merged-map IoU.
   Compared with the idealised reference of the multi-robot issue (REFERENCE_T99_S).
2. Coordinator cycle with 10 robots: the agents, the simulator and the coordinator in one
   process (no Zenoh: the cycle is what is measured, not the transport), deltas passed
   through the wire codec; the coordinator's cycle time (merge + frontiers + costs +
   assignment) per cycle.
"""

from __future__ import annotations

import logging
import math
import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

# t99 in simulated seconds of the idealised reference (grid planner, perfect localisation,
# 0.5 m/s, robots 1 m apart ~2 m inside the lower-left corner), from the multi-robot issue
REFERENCE_T99_S = {
    ("data:loop", 1): 462.0,
    ("data:cross", 1): 698.0,
    ("data:maze", 1): 1185.0,
    ("data:zigzag", 1): 1385.0,
    ("data:loop", 3): 220.0,
    ("data:cross", 3): 276.0,
    ("data:maze", 3): 429.0,
    ("data:zigzag", 3): 1309.0,
}
REFERENCE_SLACK = 1.5  # our t99 may be at most this times the reference
DATA_WORLDS = ("data:loop", "data:cross", "data:maze", "data:zigzag")
NEAREST_WORLDS = ("data:maze", "data:loop")  # where hungarian must beat nearest by 25%


@dataclass(frozen=True)
class RunSpec:
    world: str
    robots: int
    strategy: str
    seed: int


def plan_runs(
    worlds: list[str], robots: list[int], seeds: int, nearest: bool, first_seed: int = 0
) -> list[RunSpec]:
    """World x robot count (hungarian) x seed (``first_seed`` .. ``first_seed + seeds -
    1``), plus 3-robot ``nearest`` on NEAREST_WORLDS."""
    seed_range = range(first_seed, first_seed + seeds)
    runs = [RunSpec(w, n, "hungarian", s) for w in worlds for n in robots for s in seed_range]
    if nearest:
        runs += [
            RunSpec(w, max(robots), "nearest", s)
            for w in worlds
            if w in NEAREST_WORLDS and max(robots) > 1
            for s in seed_range
        ]
    return runs


def run_exploration(spec: RunSpec, out: Path, speed: float, wall_limit_s: float) -> dict:
    from polyswarm.runners.launch import LaunchOptions, launch

    opts = LaunchOptions(
        world=spec.world,
        robots=spec.robots,
        strategy=spec.strategy,
        seed=spec.seed,
        speed=speed,
        wall_limit_s=wall_limit_s,
        stop_coverage=0.99,  # t99 is what is measured; returning home is not
        out=out,
    )
    m = launch(opts).metrics
    return {
        "world": spec.world,
        "robots": spec.robots,
        "strategy": spec.strategy,
        "seed": spec.seed,
        "t90_s": m["t90_s"],
        "t99_s": m["t99_s"],
        "final_coverage": m["final_coverage"],
        "map_iou": m["map_iou"],
        "wall_collisions": m["collisions"]["walls"],
        "robot_collisions": m["collisions"]["robots"],
        "crashed_processes": m["crashed_processes"],
        "wall_time_s": m["wall_time_s"],
        "coordinator_cycle_p95_ms": m["coordinator_cycle_p95_ms"],
        "bytes_sent_per_robot": m["bytes_sent_per_robot"],
        "out": str(out),
    }


def _median_or_none(values: list[float | None]) -> float | None:
    """Median t99 over seeds; a run that never reached 99% makes the median undefined
    only if it is the majority (it counts as +inf)."""
    if not values:
        return None
    v = sorted(math.inf if x is None else x for x in values)
    med = statistics.median(v)
    return None if math.isinf(med) else float(med)


def summarise(rows: list[dict]) -> dict:
    t99: dict[str, dict[str, float | None]] = {}
    groups: dict[tuple[str, int, str], list] = {}
    for r in rows:
        groups.setdefault((r["world"], r["robots"], r["strategy"]), []).append(r["t99_s"])
    for (w, n, s), vals in sorted(groups.items()):
        t99.setdefault(w, {})[f"{n}_{s}"] = _median_or_none(vals)
    ratio_3_vs_1, ratio_vs_nearest, vs_reference = {}, {}, {}
    for w, d in t99.items():
        one, three, near = d.get("1_hungarian"), d.get("3_hungarian"), d.get("3_nearest")
        if one and three:
            ratio_3_vs_1[w] = three / one
        if three and near:
            ratio_vs_nearest[w] = three / near
        for n in (1, 3):
            ref, ours = REFERENCE_T99_S.get((w, n)), d.get(f"{n}_hungarian")
            if ref and ours:
                vs_reference[f"{w}/{n}"] = ours / ref
    ious = [r["map_iou"] for r in rows if r["map_iou"] is not None]
    return {
        "runs": len(rows),
        "success_rate": (sum(r["t99_s"] is not None for r in rows) / len(rows) if rows else None),
        "t99_s": t99,
        "t99_ratio_3_vs_1": ratio_3_vs_1,
        "t99_ratio_vs_nearest": ratio_vs_nearest,
        "t99_ratio_vs_reference": vs_reference,
        "map_iou_min": min(ious) if ious else None,
        "wall_collisions": sum(r["wall_collisions"] for r in rows),
        "crashed_runs": sum(bool(r["crashed_processes"]) for r in rows),
        "wall_time_s_max": {
            w: max(r["wall_time_s"] for r in rows if r["world"] == w)
            for w in {r["world"] for r in rows}
        },
    }


# --- coordinator cycle under load -------------------------------------------------------------


def coordinator_cycles(
    world_name: str = "data:maze", robots: int = 10, sim_s: float = 60.0, seed: int = 0
) -> dict:
    """Explore ``world_name`` with ``robots`` robots in one process; the coordinator's
    cycle times (ms) including the merges since the previous cycle."""
    from polyswarm.benchmarks.inproc import explore_in_process

    run = explore_in_process(world_name, robots, sim_s, seed)
    ms = np.array(run.coordinator.cycle_ms[1:] or [0.0])
    return {
        "world": world_name,
        "robots": robots,
        "sim_time_s": sim_s,
        "cycles": int(ms.size),
        "cycle_p50_ms": float(np.percentile(ms, 50)),
        "cycle_p95_ms": float(np.percentile(ms, 95)),
        "cycle_max_ms": float(ms.max()),
        "merged_cells": len(run.coordinator.merged.cells),
        "explored_m2": run.coordinator.merged.explored_area(),
        "robot_delta_bytes": run.delta_bytes,
    }


def run(
    worlds: list[str],
    robots: list[int],
    seeds: int,
    nearest: bool,
    speed: float,
    wall_limit_s: float,
    out: Path | None,
    load_robots: int,
    load_sim_s: float,
    on_run: Callable[[int, int, RunSpec, dict | None], None] | None = None,
    first_seed: int = 0,
) -> dict:
    out = out or Path(tempfile.mkdtemp(prefix="polyswarm-bench-explore-"))
    runs = plan_runs(worlds, robots, seeds, nearest, first_seed)
    rows = []
    for k, spec in enumerate(runs):
        if on_run:
            on_run(k, len(runs), spec, None)
        folder = out / f"{spec.world.replace(':', '_')}-{spec.robots}-{spec.strategy}-{spec.seed}"
        t0 = time.monotonic()
        row = run_exploration(spec, folder, speed, wall_limit_s)
        log.info("%s: t99 %s s in %.0f s wall", spec, row["t99_s"], time.monotonic() - t0)
        rows.append(row)
        if on_run:
            on_run(k, len(runs), spec, row)
    res = summarise(rows)
    res["runs_detail"] = rows
    res["reference_t99_s"] = {f"{w}/{n}": v for (w, n), v in REFERENCE_T99_S.items()}
    res["out"] = str(out)
    if load_robots > 0:
        load = coordinator_cycles(robots=load_robots, sim_s=load_sim_s)
        res["coordinator_load"] = load
        res[f"coordinator_cycle_p95_ms_{load_robots}_robots"] = load["cycle_p95_ms"]
    return res
