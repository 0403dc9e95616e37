"""``polyswarm bench cells``: the cell size, chosen by merge cost against delta bytes.

PolySLAM runs over a CARMEN log once per cell size; for each: the keyframe merge time
(p50, p95), the bytes of all map deltas (what a robot sends) and of the final map.
Smaller cells make smaller deltas (a keyframe re-sends only the cells it changed) but
more cells to merge and to index; larger cells the reverse.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from polyswarm.config import Config


def run(log_path: Path, sizes_m: list[float], seed: int = 0) -> dict:
    from polyswarm.io.carmen import read_carmen
    from polyswarm.slam.odometry import IncrementNoise, noisy_odometry
    from polyswarm.slam.polyslam import PolySlam
    from protocols.mapcodec import encode_delta, encode_map

    log = read_carmen(log_path)
    ref = log.reference
    odom = noisy_odometry(ref, IncrementNoise(), seed)
    out = {}
    for size in sizes_m:
        cfg = Config()
        cfg = dataclasses.replace(cfg, map=dataclasses.replace(cfg.map, cell_size_m=size))
        slam = PolySlam(cfg.slam, size, initial_pose=ref[0])
        merge_ms, delta_bytes, cells = [], 0, []
        for k, s in enumerate(log.scans):
            step = slam.process(s.scan, odom[k])
            if step.delta is not None:
                merge_ms.append(step.timings_ms.get("merge", 0.0))
                delta_bytes += len(encode_delta(step.delta))
                cells.append(len(step.delta.cells))
        out[f"{size:g}"] = {
            "cell_size_m": size,
            "keyframes": len(merge_ms),
            "merge_p50_ms": float(np.percentile(merge_ms, 50)),
            "merge_p95_ms": float(np.percentile(merge_ms, 95)),
            "delta_bytes": delta_bytes,
            "cells_per_delta_mean": float(np.mean(cells)),
            "map_bytes": len(encode_map(slam.map)),
            "map_cells": len(slam.map.cells),
        }
    return {"log": log_path.name, "sizes": out}
