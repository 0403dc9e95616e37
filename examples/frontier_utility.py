"""t99 of whole explorations in one process, with and without the frontier-area utility.

    python examples/frontier_utility.py data:maze 3 0:5 [WEIGHTS]

Runs ``explore_in_process`` (simulator, agents and coordinator in one process, no
Zenoh) for each seed in the range and each weight of ``polyswarm.explore.GAIN_WEIGHT``
(metres of path per m2 of unexplored area behind a frontier; default "0,1": the
length alone, then with the area), two runs at a time, and prints the simulated
seconds to 99 % of the free space. In one process the runs are deterministic, so two
weights compare seed by seed. The README's comparison table came from a copy of this
script that also logged targets and assignments. A 3-robot maze run takes about 10
minutes of wall time here.
"""

from __future__ import annotations

import sys
from multiprocessing import Pool

import numpy as np

SIM_LIMIT_S = 3000.0  # simulated seconds: a run that has not reached 99 % by then failed


def t99(args: tuple[str, int, int, float]) -> tuple[float, int, float | None]:
    world, robots, seed, weight = args
    import polyswarm.explore
    from polyswarm.benchmarks.inproc import explore_in_process

    polyswarm.explore.GAIN_WEIGHT = weight  # this worker process only
    run = explore_in_process(world, robots, SIM_LIMIT_S, seed=seed, stop_coverage=0.99)
    return weight, seed, next((t for t, c in run.coverage if c >= 0.99), None)


def main(world: str = "data:maze", robots: str = "3", seeds: str = "0:5", weights="0,1") -> None:
    a, b = (int(v) for v in seeds.split(":"))
    jobs = [(world, int(robots), s, float(w)) for w in weights.split(",") for s in range(a, b)]
    with Pool(2) as pool:  # this machine's two cores
        results = pool.map(t99, jobs, chunksize=1)
    for w in sorted({r[0] for r in results}):
        rows = sorted((s, t) for ww, s, t in results if ww == w)
        done = [t for _, t in rows if t is not None]
        per_seed = ", ".join("never" if t is None else f"{t:.0f}" for _, t in rows)
        median = f"{np.median(done):.0f} s" if len(done) == len(rows) else "-"
        print(f"GAIN_WEIGHT {w:g}: t99 {per_seed} s (median {median})")


if __name__ == "__main__":
    main(*sys.argv[1:])
