"""What noding cell borders costs, side by side: the merge stage of PolySLAM and the
coordinator's batch merge, with ``polymap._node_borders`` on and replaced by a no-op.

    python examples/node_borders_cost.py [../shared/data/logs/freiburg-101-corrected.log.gz]

Noding makes a border vector end where explored space across the border starts or
ends, so only its part facing unexplored space stays a frontier (README, Exploration).
"""

from __future__ import annotations

import statistics
import sys
import time

import numpy as np

import polyswarm.polymap as pm
from polyswarm.config import Config
from polyswarm.io.carmen import read_carmen
from polyswarm.slam.polyslam import PolySlam

SCANS = 1200  # the first scans of the log (about 280 keyframes)
BATCH = 150  # cells per coordinator merge (one flush of several robots' changes)


def main(path: str = "../shared/data/logs/freiburg-101-corrected.log.gz") -> None:
    noded, plain = pm._node_borders, lambda idxs, regions, *_: regions
    cfg = Config()
    log = read_carmen(path)
    slam_ms: dict[str, list[float]] = {"noded": [], "plain": []}
    merge_ms: dict[str, list[float]] = {"noded": [], "plain": []}
    opts = pm.MergeOptions(obstacle_snap_m=cfg.slam.obstacle_snap_m)
    for _ in range(2):  # alternate, so both see the same machine
        for name, fn in (("noded", noded), ("plain", plain)):
            pm._node_borders = fn
            slam = PolySlam(cfg.slam, cfg.map.cell_size_m, initial_pose=log.reference[0])
            for k, s in enumerate(log.scans[:SCANS]):
                step = slam.process(s.scan, log.reference[k])
                if step.keyframe:
                    slam_ms[name].append(step.timings_ms["merge"])
            cells = list(slam.map.cells.values())
            merged = pm.GridPolyMap(cfg.map.cell_size_m)
            for i in range(0, len(cells), BATCH):
                t0 = time.perf_counter()
                merged = merged.merge_cells(cells[i : i + BATCH], opts).map
                merge_ms[name].append((time.perf_counter() - t0) * 1e3)
    pm._node_borders = noded
    for what, d in (
        ("PolySLAM merge stage per keyframe", slam_ms),
        ("merge_cells per batch", merge_ms),
    ):
        for name, v in d.items():
            print(
                f"{what:36s} {name}: median {statistics.median(v):6.1f} ms, "
                f"p95 {np.percentile(v, 95):6.1f} ms (n={len(v)})"
            )


if __name__ == "__main__":
    main(*sys.argv[1:])
