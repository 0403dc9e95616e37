"""The merge stage alone (trim, snap to the wire's grid, merge), replayed on the keyframes
of a recorded SLAM run: timings per keyframe and the final map's digest, to compare two
versions of the code on the same input (a change that must not change the map keeps the
digest).

    python examples/merge_stage_replay.py record data:maze /tmp/maze-keyframes.pkl
    python examples/merge_stage_replay.py replay /tmp/maze-keyframes.pkl [N]

``record`` runs PolySLAM along the world's coverage route in the simulator (as ``bench
slam`` does, seed 0) and pickles every keyframe polygon the merge stage was given, with
its merge options (the maze: 3,386 keyframes, about 7 minutes). ``replay`` merges the
first N (all by default) into an empty map, with no pose-graph corrections in between.
Side by side, put the other version first on the path:
``PYTHONPATH=/path/to/other/checkout python examples/merge_stage_replay.py replay FILE``
(run from outside both checkouts, so that the working directory does not come first).
"""

from __future__ import annotations

import pickle
import sys
import time

import numpy as np


def record(world: str, out: str) -> None:
    import polyswarm.slam.polyslam as slam_module
    from polyswarm.config import Config
    from polyswarm.runners.slam import run_world

    given = []
    trim = slam_module.trim_keyframe

    def recording(kf, pmap, options):
        given.append((kf, options))
        return trim(kf, pmap, options)

    slam_module.trim_keyframe = recording
    run_world(world, Config(), seed=0)
    with open(out, "wb") as f:
        pickle.dump(given, f)
    print(f"{len(given)} keyframes of {world} -> {out}")


def replay(path: str, n: int | None) -> None:
    from polyswarm.config import Config
    from polyswarm.errors import PolyswarmError
    from polyswarm.polymap import GridPolyMap, cells_digest, snap_polygon
    from polyswarm.slam.polyslam import UNITS_PER_M
    from polyswarm.slam.trim import trim_keyframe

    with open(path, "rb") as f:
        given = pickle.load(f)[:n]
    cfg = Config()
    quantum = round(cfg.slam.merge_quantum_m * UNITS_PER_M)
    pmap = GridPolyMap(cfg.map.cell_size_m)
    trim_ms, merge_ms, refused = [], [], 0
    for kf, options in given:
        t0 = time.perf_counter()
        news = trim_keyframe(kf, pmap, options)
        t1 = time.perf_counter()
        snapped = snap_polygon(news, quantum)  # as PolySlam.process: the polygon sent
        try:
            pmap = pmap.merge(news if snapped is None else snapped, options).map
        except PolyswarmError:
            refused += 1
        t2 = time.perf_counter()
        trim_ms.append((t1 - t0) * 1e3)
        merge_ms.append((t2 - t1) * 1e3)
    both = np.add(trim_ms, merge_ms)
    for name, ms in (("trim", trim_ms), ("merge", merge_ms), ("both", both)):
        print(f"{name:5s} p50 {np.median(ms):6.2f} ms  p95 {np.percentile(ms, 95):6.2f} ms")
    print(f"{len(both)} keyframes in {both.sum() / 1e3:.1f} s, {refused} refused")
    print(f"map digest {cells_digest(pmap.cells.values()):08x}, {len(pmap.cells)} cells")


if __name__ == "__main__":
    if len(sys.argv) >= 4 and sys.argv[1] == "record":
        record(sys.argv[2], sys.argv[3])
    elif len(sys.argv) >= 3 and sys.argv[1] == "replay":
        replay(sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else None)
    else:
        sys.exit(__doc__)
