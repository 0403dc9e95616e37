"""Where the coordinator's cycle goes: per-stage timers on the 10-robot load run.

    python examples/coordinator_stages.py [SIM_SECONDS]

Runs what ``polyswarm bench explore --worlds "" --load-robots 10`` runs (10 robots on
the maze, in one process) and prints, per coordinator cycle, the time spent merging
robot cells, updating the navigation graph, finding frontier targets (and within that:
extracting the frontier vectors, their facts, the unexplored area behind them) and
computing path costs (p50 and p95 of each, milliseconds), and how much work was skipped: robot
cells that could not change the merged map, frontiers whose facts were reused. To
compare two versions side by side, run it from both checkouts at once
(``PYTHONPATH=/path/to/other/checkout python examples/coordinator_stages.py``; the
counts need a version that has them).
"""

from __future__ import annotations

import sys
import time
from collections import defaultdict

import numpy as np

import agents.coordinator as coordinator_module
import polyswarm.explore.assign as explore_module
import polyswarm.explore.targets as targets_module
from polyswarm.benchmarks.inproc import explore_in_process
from polyswarm.nav.navgraph import NavGraph
from polyswarm.polymap import GridPolyMap

spent: dict[str, float] = defaultdict(float)  # ms per stage since the last cycle
counts: dict[str, int] = defaultdict(int)
state = {"in_flush": False}  # inside the coordinator's flush (merge + graph update)


def timed(owner, name: str, stage: str, only_in_flush: bool = False) -> None:
    """Wrap ``owner.name`` so that its time adds to ``spent[stage]``."""
    inner = getattr(owner, name)

    def wrapper(*args, **kwargs):
        if only_in_flush and not state["in_flush"]:  # the agents update graphs of their own
            return inner(*args, **kwargs)
        t0 = time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            spent[stage] += (time.perf_counter() - t0) * 1e3

    setattr(owner, name, wrapper)


def counted(owner, name: str, arrived: str, kept: str) -> None:
    """Count the items ``owner.name`` gets (first list argument) and returns."""
    inner = getattr(owner, name, None)
    if inner is None:  # an older version without this step
        return

    def wrapper(*args, **kwargs):
        items = next(a for a in args if isinstance(a, list))
        out = inner(*args, **kwargs)
        counts[arrived] += len(items)
        counts[kept] += len(out)
        return out

    setattr(owner, name, wrapper)


def main(sim_s: float = 60.0) -> None:
    Coordinator = coordinator_module.Coordinator
    flush = Coordinator.flush

    def flagged_flush(self):
        state["in_flush"] = True
        try:
            return flush(self)
        finally:
            state["in_flush"] = False

    Coordinator.flush = flagged_flush
    timed(Coordinator, "_merge_batch", "merge")
    timed(NavGraph, "update", "graph", only_in_flush=True)
    timed(explore_module.Reach, "costs", "costs")
    timed(coordinator_module, "frontier_targets", "targets")
    counted(GridPolyMap, "_cells_that_change", "robot cells", "robot cells that change")
    counted(targets_module, "_segment_facts", "frontiers recomputed", "_")
    extract = targets_module.extract_frontiers

    def counted_extract(*args, **kwargs):  # only the coordinator looks for frontiers
        segs = extract(*args, **kwargs)
        counts["frontiers"] += len(segs)
        return segs

    targets_module.extract_frontiers = counted_extract
    # the parts of ``targets``
    timed(targets_module, "extract_frontiers", "extract")
    timed(targets_module, "_segment_facts", "facts")
    timed(targets_module, "unexplored_behind", "behind")
    rows: list[dict] = []
    cycle = Coordinator.cycle

    def recorded_cycle(self):
        out = cycle(self)
        rows.append({**spent, "total": self.cycle_ms[-1]})
        spent.clear()
        return out

    Coordinator.cycle = recorded_cycle
    explore_in_process("data:maze", 10, sim_s, seed=0)
    rows = rows[1:]  # the first cycle merges the robots' first scans
    print(f"{len(rows)} cycles, 10 robots, maze, {sim_s:.0f} simulated s")
    for stage in ("total", "merge", "graph", "targets", "extract", "facts", "behind", "costs"):
        v = np.array([r.get(stage, 0.0) for r in rows])
        print(
            f"{stage:>8}: p50 {np.percentile(v, 50):6.1f} ms   p95 {np.percentile(v, 95):6.1f} ms"
        )
    if counts["robot cells"]:
        n, k = counts["robot cells"], counts["robot cells that change"]
        print(f"robot cells merged: {n}, skipped as unable to change the map: {1 - k / n:.0%}")
    if counts["frontiers recomputed"]:
        n, k = counts["frontiers"], counts["frontiers recomputed"]
        print(f"frontiers over all cycles: {n}, facts reused: {1 - k / n:.0%}")


if __name__ == "__main__":
    main(*(float(a) for a in sys.argv[1:]))
