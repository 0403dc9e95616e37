"""t99 of whole explorations in one process, by assignment strategy.

    python examples/strategies_in_one_process.py data:maze 3 0:5 hungarian,nearest

Runs ``explore_in_process`` (simulator, agents and coordinator in one process, no
Zenoh; deterministic per seed) for each seed in the range and each strategy
(``explore.strategy``), two runs at a time, and prints the simulated seconds to 99 % of
the free space with the medians. A 3-robot maze run takes 5-18 minutes of wall time here.
"""

from __future__ import annotations

import dataclasses
import sys
from multiprocessing import Pool

import numpy as np

SIM_LIMIT_S = 3000.0  # simulated seconds: a run that has not reached 99 % by then failed


def t99(args: tuple[str, int, int, str]) -> tuple[str, int, float | None]:
    world, robots, seed, strategy = args
    from polyswarm.benchmarks.inproc import explore_in_process
    from polyswarm.config import Config
    from polyswarm.evaluation.coverage import time_to_coverage

    cfg = Config()
    cfg = dataclasses.replace(cfg, explore=dataclasses.replace(cfg.explore, strategy=strategy))
    run = explore_in_process(world, robots, SIM_LIMIT_S, seed=seed, cfg=cfg, stop_coverage=0.99)
    return strategy, seed, time_to_coverage(run.coverage, 0.99)


def main(
    world: str = "data:maze",
    robots: str = "3",
    seeds: str = "0:5",
    strategies: str = "hungarian,nearest",
) -> None:
    a, b = (int(v) for v in seeds.split(":"))
    jobs = [(world, int(robots), s, st) for st in strategies.split(",") for s in range(a, b)]
    with Pool(2) as pool:  # this machine's two cores
        results = pool.map(t99, jobs, chunksize=1)
    for st in strategies.split(","):
        rows = sorted((s, t) for key, s, t in results if key == st)
        done = [t for _, t in rows if t is not None]
        per_seed = ", ".join("never" if t is None else f"{t:.0f} s" for _, t in rows)
        med = f"{np.median(done):.0f} s" if done else "-"
        print(f"{st}: {per_seed}; median {med} ({len(done)}/{len(rows)} reached 99 %)")


if __name__ == "__main__":
    main(*sys.argv[1:])
