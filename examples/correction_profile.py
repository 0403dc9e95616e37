"""Where one loop correction of the map spends its time, and what submaps would save.

    python examples/correction_profile.py freiburg-101 [--groups 5,10,20]

Runs PolySLAM on a shared log (real wheel odometry, the default config) and profiles
every correction the map follows (``polyswarm.slam.follow.apply_moves``): the corrections'
p50 / p95 against the keyframe p95 of the same run, and the functions that took the most
of their time. Then it unites the keyframe polygons each correction merged again (the
union ``merge_many`` makes of them) in groups of G consecutive keyframes first, as
submaps moved as one would hold them, and prints how long the union of the groups takes
against the union of the keyframes (the groups' own unions are not counted: a submap
would have them before the correction).
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time

import numpy as np

from polyswarm.config import Config
from polyswarm.data import log_paths
from polyswarm.polymap import PRECISION_M, merge
from polyswarm.runners.slam import OdometrySource, run_log
from polyswarm.slam.polyslam import follow


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", help="a shared log's name or its start, e.g. freiburg-101")
    ap.add_argument("--groups", default="5,10,20", help="keyframes per submap, comma-separated")
    ap.add_argument("--top", type=int, default=15, help="functions listed")
    args = ap.parse_args()
    path = next(p for p in log_paths() if p.name.startswith(args.log))

    profile, ms, unions = cProfile.Profile(), [], []
    inside = [False]
    apply_moves, union_all = follow.apply_moves, merge.shapely.union_all

    def timed_apply_moves(*a, **k):
        t0 = time.perf_counter()
        inside[0] = True
        profile.enable()
        try:
            return apply_moves(*a, **k)
        finally:
            profile.disable()
            inside[0] = False
            ms.append((time.perf_counter() - t0) * 1e3)

    def kept_union_all(geoms, *a, **k):
        if inside[0] and isinstance(geoms, list):  # merge_many's keyframes, not cell boxes
            unions.append(list(geoms))
        return union_all(geoms, *a, **k)

    follow.apply_moves = timed_apply_moves
    merge.shapely.union_all = kept_union_all
    try:
        run = run_log(path, Config(), odometry=OdometrySource.LOG)
    finally:
        follow.apply_moves, merge.shapely.union_all = apply_moves, union_all
    if not ms:
        print("no correction in this run")
        return
    print(
        f"{path.name}: {len(ms)} corrections, p50 {np.median(ms):.0f} ms, "
        f"p95 {np.percentile(ms, 95):.0f} ms, all {sum(ms) / 1e3:.2f} s; "
        f"keyframe p95 {np.percentile(run.keyframe_ms, 95):.0f} ms"
    )
    pstats.Stats(profile).sort_stats("cumulative").print_stats(args.top)

    def unite(geoms) -> float:
        t0 = time.perf_counter()
        union_all(geoms, grid_size=PRECISION_M)
        return time.perf_counter() - t0

    direct = sum(unite(g) for g in unions)
    print(f"union of the keyframes merged again ({len(unions)} unions): {direct * 1e3:.0f} ms")
    for size in (int(s) for s in args.groups.split(",")):
        groups = [
            [union_all(g[i : i + size], grid_size=PRECISION_M) for i in range(0, len(g), size)]
            for g in unions
        ]
        grouped = sum(unite(g) for g in groups)
        print(f"  in submaps of {size}: {grouped * 1e3:.0f} ms ({direct / grouped:.1f} x faster)")


if __name__ == "__main__":
    main()
