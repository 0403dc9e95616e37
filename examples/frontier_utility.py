"""t99 of whole explorations in one process, with and without the frontier-area utility.

    python examples/frontier_utility.py data:maze 3 0:5 [WEIGHTS] [RADII]

Runs ``explore_in_process`` (simulator, agents and coordinator in one process, no
Zenoh) for each seed in the range, each weight of ``polyswarm.explore.targets.GAIN_WEIGHT``
(metres of path per m2 of unexplored area behind a frontier; default "0,1": the
length alone, then with the area) and each radius of ``GAIN_RADIUS_M`` (metres the
area is counted behind the frontier; default: the library's), two runs at a time, and
prints the simulated seconds to 99 % of the free space. In one process the runs are
deterministic, so two settings compare seed by seed. The README's weight comparison
(radius 3 m) came from a copy of this script that also logged targets and
assignments; its radius comparison is
``python examples/frontier_utility.py data:maze 3 0:5 1 3,6``. A 3-robot maze run
takes 5-15 minutes of wall time here.
"""

from __future__ import annotations

import sys
from multiprocessing import Pool

import numpy as np

SIM_LIMIT_S = 3000.0  # simulated seconds: a run that has not reached 99 % by then failed


def t99(args: tuple[str, int, int, float, float]) -> tuple[tuple, int, float | None]:
    world, robots, seed, weight, radius = args
    import polyswarm.explore.targets
    from polyswarm.benchmarks.inproc import explore_in_process
    from polyswarm.evaluation.coverage import time_to_coverage

    polyswarm.explore.targets.GAIN_WEIGHT = weight  # this worker process only
    polyswarm.explore.targets.GAIN_RADIUS_M = radius
    run = explore_in_process(world, robots, SIM_LIMIT_S, seed=seed, stop_coverage=0.99)
    return (weight, radius), seed, time_to_coverage(run.coverage, 0.99)


def main(
    world: str = "data:maze",
    robots: str = "3",
    seeds: str = "0:5",
    weights: str = "0,1",
    radii: str | None = None,
) -> None:
    from polyswarm.explore.targets import GAIN_RADIUS_M

    a, b = (int(v) for v in seeds.split(":"))
    jobs = [
        (world, int(robots), s, float(w), float(r))
        for w in weights.split(",")
        for r in (radii or str(GAIN_RADIUS_M)).split(",")
        for s in range(a, b)
    ]
    with Pool(2) as pool:  # this machine's two cores
        results = pool.map(t99, jobs, chunksize=1)
    for w, r in sorted({res[0] for res in results}):
        rows = sorted((s, t) for key, s, t in results if key == (w, r))
        done = [t for _, t in rows if t is not None]
        per_seed = ", ".join("never" if t is None else f"{t:.0f} s" for _, t in rows)
        median = f"{np.median(done):.0f} s" if len(done) == len(rows) else "-"
        print(f"GAIN_WEIGHT {w:g}, GAIN_RADIUS_M {r:g}: t99 {per_seed} (median {median})")


if __name__ == "__main__":
    main(*sys.argv[1:])
