"""Planning time on a whole map: random start/goal pairs in its explored space.

    python examples/plan_timing.py runs/<launch>/map.polymap [PAIRS]

The graph is built once (its time is printed too); each pair is planned with A* over
the convex cells and a funnel.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from polyswarm.config import Config
from polyswarm.errors import PlanningError
from polyswarm.nav.navgraph import NavGraph
from polyswarm.nav.planner import Planner
from protocols.files import read_polymap


def main(path: str, pairs: str = "20") -> None:
    pmap = read_polymap(path)
    cfg = Config()
    t0 = time.perf_counter()
    graph = NavGraph.build(pmap, cfg.nav.robot_radius_m + cfg.nav.clearance_margin_m)
    print(f"navigation graph built in {(time.perf_counter() - t0) * 1e3:.0f} ms")
    planner = Planner(pmap, graph)
    rng = np.random.default_rng(0)
    x0, y0, x1, y1 = pmap.bounds()
    points: list[np.ndarray] = []
    while len(points) < 2 * int(pairs):
        q = rng.uniform([x0, y0], [x1, y1])
        if pmap.is_free(*q):
            points.append(q)
    times_ms, lengths = [], []
    for a, b in zip(points[::2], points[1::2], strict=True):
        t0 = time.perf_counter()
        try:
            lengths.append(planner.plan(a, b).length_m)
        except PlanningError:
            lengths.append(float("nan"))
        times_ms.append((time.perf_counter() - t0) * 1e3)
    print(
        f"planning ms: p50 {np.median(times_ms):.0f}, p95 {np.percentile(times_ms, 95):.0f}, "
        f"max {max(times_ms):.0f}; path lengths (m): {np.round(lengths, 1).tolist()}"
    )


if __name__ == "__main__":
    main(*sys.argv[1:])
