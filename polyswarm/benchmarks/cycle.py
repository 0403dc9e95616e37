"""``polyswarm bench cycle``: the coordinator's cycle, all its work included, per world.

Each run explores one world with N robots in one process (``inproc``: simulator, agents
and coordinator wired directly, deltas through the wire codec) until the mission ends or
a simulated time limit. A cycle's time is all the work the coordinator's thread did since
the previous cycle: replaying the robots' merges and corrections on its copies of their
maps (or, with replay processes, ``agents.replay``, sending them there and taking in the
cells they changed: the processes' processor time and the lag they add are reported
beside), merging them into the merged map (or, with a merge process, ``agents.merger``,
sending it the cells and applying what it changed: its processor time and lag beside),
and the cycle's planning (frontiers, costs, assignment). In one process nothing competes
with the coordinator while it works, so these are its own costs; ``bench load`` measures
it among ten robot processes.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

# the targets of the fleet issue: p95 per robot count (ms)
TARGET_P95_MS = {3: 100.0, 10: 100.0, 25: 250.0}


def coordinator_cycles(
    world_name: str = "data:maze",
    robots: int = 10,
    sim_s: float = 60.0,
    seed: int = 0,
    replay_workers: int = 1,
    merge_process: bool = True,
) -> dict:
    """Explore ``world_name`` with ``robots`` robots in one process; the coordinator's
    cycle times (ms) including all the work in its thread since the previous cycle
    (replaying robots' merges, merging, planning), and each stage's share of it. With
    ``replay_workers`` processes the replays run on them (``agents.replay``); the
    thread's share is sending updates and taking in the cells, and the processes'
    processor time is reported beside it; likewise the merge process's."""
    from polyswarm.benchmarks.inproc import explore_in_process

    run = explore_in_process(
        world_name, robots, sim_s, seed, replay_workers=replay_workers, merge_process=merge_process
    )
    c = run.coordinator
    ms = np.array(c.cycle_ms[1:] or [0.0])
    cpu = np.array(c.cycle_cpu_ms[1:] or [0.0])
    return {
        "world": world_name,
        "robots": robots,
        "sim_time_s": run.sim_time_s,
        "final_coverage": run.coverage[-1][1] if run.coverage else 0.0,
        "cycles": int(ms.size),
        "cycle_p50_ms": float(np.percentile(ms, 50)),
        "cycle_p95_ms": float(np.percentile(ms, 95)),
        "cycle_max_ms": float(ms.max()),
        "cycle_cpu_p95_ms": float(np.percentile(cpu, 95)),
        "replayed_merges": c.replayed_merges,
        "replay_workers": replay_workers,
        "replay_workers_cpu_s": sum(c.worker_replay_cpu_ms) / 1e3,
        # how late the robots' cells reach the coordinator's copies through the pool
        "replay_lag_p50_ms": _pct(c.replay_lag_ms, 50),
        "replay_lag_p95_ms": _pct(c.replay_lag_ms, 95),
        "merge_process": merge_process,
        "merge_process_cpu_s": sum(c.merger_cpu_ms) / 1e3,
        # how late a merge reaches the coordinator's map: sent to applied
        "merge_lag_p50_ms": _pct(c.merge_lag_ms, 50),
        "merge_lag_p95_ms": _pct(c.merge_lag_ms, 95),
        "corrections": c.corrections,
        "merged_cells": len(c.merged.cells),
        "explored_m2": c.merged.explored_area(),
        "robot_delta_bytes": run.delta_bytes,
        "stage_share": c.stage_shares(),
    }


def run(
    worlds: tuple[str, ...],
    robots: int,
    sim_s: float,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
    replay_workers: int = 1,
    merge_process: bool = True,
) -> dict:
    rows = {}
    for w in worlds:
        if progress:
            progress(f"{w}, {robots} robots")
        rows[w] = coordinator_cycles(w, robots, sim_s, seed, replay_workers, merge_process)
    p95 = [r["cycle_p95_ms"] for r in rows.values()]
    target = TARGET_P95_MS.get(robots)
    return {
        "robots": robots,
        "replay_workers": replay_workers,
        "merge_process": merge_process,
        "seed": seed,
        "sim_limit_s": sim_s,
        "worlds": rows,
        "cycle_p95_ms_worst": max(p95) if p95 else None,
        "target_p95_ms": target,
        "worlds_within_target": None if target is None else sum(p <= target for p in p95),
    }


def _pct(values: list[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None
