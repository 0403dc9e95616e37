"""A whole exploration in one process (no Zenoh): simulator, agents and coordinator.

    python examples/explore_in_one_process.py rooms 2 120

Handy to step through the pipeline in a debugger; ``polyswarm launch`` runs the same
parts as separate processes over Zenoh.
"""

from __future__ import annotations

import sys

from polyswarm.benchmarks.inproc import explore_in_process
from polyswarm.io.export import export_map


def main(world: str = "rooms", robots: str = "2", seconds: str = "120") -> None:
    run = explore_in_process(world, int(robots), float(seconds), stop_coverage=0.99)
    t, cov = run.coverage[-1]
    print(f"{world}: {100 * cov:.1f} % of the free space after {t:.0f} simulated s")
    export_map(run.coordinator.merged, "explored.png")
    print("merged map written to explored.png")


if __name__ == "__main__":
    main(*sys.argv[1:])
