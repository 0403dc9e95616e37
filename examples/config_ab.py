"""t99 of whole explorations in one process under two or more values of a config field.

    python examples/config_ab.py data:cross 1 0:6 slam.obstacle_snap_behind_m=0.1,0.15

Runs ``explore_in_process`` (simulator, agents and coordinator in one process, no
Zenoh) for each seed in the range and each value of the field (a dotted path into
``polyswarm.config.Config``), two runs at a time (this machine's two cores), and prints
the simulated seconds to 99 % of the free space, seed by seed. In one process a run is
deterministic, so the values compare seed by seed; with every part its own process
(``polyswarm launch -c FILE.toml``) the processes' timing adds its own spread.
"""

from __future__ import annotations

import sys
import time
from multiprocessing import Pool

SIM_LIMIT_S = 3000.0  # simulated seconds: a run that has not reached 99 % by then failed


def nested(path: list[str], value) -> dict:
    """``{"a": {"b": value}}`` for the path ``["a", "b"]``: a config override."""
    return {path[0]: nested(path[1:], value)} if len(path) > 1 else {path[0]: value}


def t99(job: tuple[str, int, int, str, float]) -> tuple[float, int, float | None]:
    world, robots, seed, field, value = job
    from polyswarm.benchmarks.inproc import explore_in_process
    from polyswarm.config import Config, with_overrides
    from polyswarm.evaluation.coverage import time_to_coverage

    # validated like a TOML file: an unknown field or a bad value is a ConfigError
    cfg = with_overrides(Config(), nested(field.split("."), value))
    t0 = time.monotonic()
    run = explore_in_process(world, robots, SIM_LIMIT_S, seed=seed, cfg=cfg, stop_coverage=0.99)
    t = time_to_coverage(run.coverage, 0.99)
    wall_s = time.monotonic() - t0
    print(f"{field}={value} seed {seed}: t99 {t} s ({wall_s:.0f} s wall)", flush=True)
    return value, seed, t


def main(world: str, robots: str, seeds: str, assignment: str) -> None:
    field, values = assignment.split("=")
    a, b = (int(v) for v in seeds.split(":"))
    jobs = [
        (world, int(robots), s, field, float(v)) for s in range(a, b) for v in values.split(",")
    ]
    with Pool(2) as pool:
        results = pool.map(t99, jobs, chunksize=1)
    for value in sorted({r[0] for r in results}):
        rows = sorted((s, t) for v, s, t in results if v == value)
        per_seed = ", ".join("never" if t is None else f"{t:.0f}" for _, t in rows)
        print(f"{field} = {value}: t99 by seed {per_seed} s")


if __name__ == "__main__":
    main(*sys.argv[1:])
