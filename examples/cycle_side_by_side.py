"""Compare the coordinator's work between two checkouts, side by side.

    python examples/cycle_side_by_side.py WORLD SIM_SECONDS LABEL [ROBOTS]

Explores WORLD with ROBOTS robots (default 3) in one process, as ``polyswarm bench
cycle`` does, and prints the planning and total work of the coordinator's thread
(milliseconds), the cycle's processor p50 and p95, and the final coverage and cell
digest of the merged map: equal digests mean both versions made the same map. Run it
from both checkouts at once, each with its own code first on the path:

    PYTHONPATH=/path/to/old python examples/cycle_side_by_side.py data:maze 250 old &
    PYTHONPATH=. python examples/cycle_side_by_side.py data:maze 250 new
"""

from __future__ import annotations

import sys

import numpy as np

from polyswarm.benchmarks.inproc import explore_in_process
from polyswarm.polymap import cells_digest


def main(world: str, sim_s: float, label: str, robots: int = 3) -> None:
    run = explore_in_process(world, robots, sim_s, 0)
    c = run.coordinator
    cpu = np.array(c.cycle_cpu_ms[1:])
    print(
        label,
        "plan_ms",
        round(c.stage_ms.get("plan", 0.0)),
        "total_ms",
        round(sum(c.stage_ms.values())),
        "cycle_cpu_p50",
        round(float(np.percentile(cpu, 50)), 1),
        "p95",
        round(float(np.percentile(cpu, 95)), 1),
        "coverage",
        round(run.coverage[-1][1], 6),
        "digest",
        cells_digest(list(c.merged.cells.values())),
        flush=True,
    )


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]), sys.argv[3], int(sys.argv[4]) if len(sys.argv) > 4 else 3)
