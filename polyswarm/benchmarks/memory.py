"""``polyswarm bench memory``: what a robot's SLAM keeps per keyframe, on the shared logs.

PolySLAM runs over each log as an agent runs it (no per-scan trajectory kept) with the
log's real wheel odometry where it has raw ODOM lines (synthetic noise otherwise), and
Python's heap (``tracemalloc``: the pose graph, keyframe store, atlas and map, numpy
arrays included; not GEOS's own memory) is read every ``EVERY_KEYFRAMES`` keyframes.
``kb_per_keyframe_second_half``: the heap's growth over the second half of the log's
keyframes, per keyframe; by then the robot mostly maps space it has mapped before, so
this is the cost of a keyframe itself rather than of new map. An agent's resident memory
over a whole mission is ``bench load``'s.
"""

from __future__ import annotations

import gc
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np

EVERY_KEYFRAMES = 50  # heap samples this many keyframes apart


def run_log(path: Path, max_keyframes: int | None = None) -> dict:
    """One log (``max_keyframes``: stop after that many, for a quick look)."""
    from polyswarm.config import Config
    from polyswarm.errors import DataFormatError
    from polyswarm.io.carmen import read_carmen, real_odometry
    from polyswarm.slam.odometry import IncrementNoise, noisy_odometry
    from polyswarm.slam.polyslam import PolySlam

    log = read_carmen(path)
    try:
        odom, source = real_odometry(log), "real"
    except DataFormatError:
        odom, source = noisy_odometry(log.reference, IncrementNoise(), 0), "synthetic"
    cfg = Config()
    slam = PolySlam(cfg.slam, cfg.map.cell_size_m, initial_pose=log.reference[0])
    rows = []
    tracemalloc.start()
    try:
        for k, s in enumerate(log.scans):
            step = slam.process(s.scan, odom[k])
            if step.keyframe and len(slam.graph) % EVERY_KEYFRAMES == 0:
                gc.collect()
                heap_mb = tracemalloc.get_traced_memory()[0] / 1e6
                rows.append((len(slam.graph), heap_mb, slam.map.explored_area()))
            if max_keyframes is not None and len(slam.graph) >= max_keyframes:
                break
    finally:
        tracemalloc.stop()
    return {"odometry": source, "scans": len(log.scans), **heap_growth(rows)}


def heap_growth(rows: list[tuple[int, float, float]]) -> dict:
    """From samples (keyframes, heap MB, explored m2): the heap per keyframe over all of
    them and over the second half, and the map's growth in that half (share)."""
    out = {"keyframes": rows[-1][0] if rows else 0, "heap_mb_last": rows[-1][1] if rows else None}
    out |= {"kb_per_keyframe": None, "kb_per_keyframe_second_half": None}
    out["area_growth_second_half"] = None
    if len(rows) < 3:
        return out
    kf, mb, area = (np.array(c, dtype=float) for c in zip(*rows, strict=True))
    h = len(kf) // 2
    out["kb_per_keyframe"] = float(1000.0 * (mb[-1] - mb[0]) / (kf[-1] - kf[0]))
    out["kb_per_keyframe_second_half"] = float(1000.0 * (mb[-1] - mb[h]) / (kf[-1] - kf[h]))
    out["area_growth_second_half"] = float((area[-1] - area[h]) / area[h])
    return out


def run(progress: Callable[[str], None] | None = None, logs: list[Path] | None = None) -> dict:
    from polyswarm.data import log_paths

    res = {}
    for path in logs if logs is not None else log_paths():
        name = path.name.split(".")[0].removesuffix("-corrected")
        if progress:
            progress(name)
        res[name] = run_log(path)
    half = [r["kb_per_keyframe_second_half"] for r in res.values()]
    half = [h for h in half if h is not None]
    return {
        "logs": res,
        "every_keyframes": EVERY_KEYFRAMES,
        "kb_per_keyframe_second_half_max": max(half) if half else None,
    }
