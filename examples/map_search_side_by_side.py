"""Map matching with the coarse-to-fine search and the one-pass fine search, side by side.

Robots explore a world at scattered starts (``polyswarm bench merge``'s recording: every
5 simulated seconds each robot's map in its own frame); at every ``STEP``-th moment
robot 1's map is matched against each other robot's twice, one search after the other
in this process (``polyswarm.frames.mapsearch.search``, then ``search_fine``), and the verdicts,
poses and times are compared:

    python examples/map_search_side_by_side.py docs/results/map-search.json \
        office:0,loop:0,cross:0,maze:0,data:loop:0 [STEP, default 3] [--images]

``--images`` also checks accepted poses against the maps' symmetric images (two more
searches a match; ``bench merge`` does, the coordinator does not).
"""

from __future__ import annotations

import json
import logging
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def _pairs(world: str, seed: int, step: int):
    from polyswarm.benchmarks.merge import _snapshots
    from polyswarm.config import Config
    from polyswarm.se2 import compose, inverse

    moments, starts, _ = _snapshots(world, seed, 3, Config())
    for t, maps in moments[::step]:
        for k in range(1, len(maps)):
            truth = compose(inverse(np.asarray(starts[0])), np.asarray(starts[k]))
            yield t, k, maps[0], maps[k], truth


def _match(a, b, search, images: bool):
    from polyswarm.frames.mapmatch import MatchError, match_maps

    t0 = time.perf_counter()
    try:
        m = match_maps(a, b, None, images=images, search=search)
    except MatchError:
        m = None
    return m, time.perf_counter() - t0


def _scored(m, truth) -> dict:
    from polyswarm.frames.mapmatch import frame_error

    e_m, e_rad = frame_error(m.pose, truth)
    return {
        "err_m": e_m,
        "err_deg": float(np.degrees(e_rad)),
        "accepted": bool(m.accepted),
        "proposed": bool(m.proposed),
        "reason": m.reason,
    }


def _wrong(m: dict) -> bool:
    """An accepted or proposed pose more than 1 m or 5 degrees off (bench merge's)."""
    return m["proposed"] and (m["err_m"] > 1.0 or m["err_deg"] > 5.0)


def main(out: str, runs: str, step: int = 3, images: bool = False) -> None:
    from polyswarm.frames.mapsearch import search, search_fine
    from polyswarm.se2 import wrap

    logging.disable(logging.WARNING)
    rows = []
    for run in runs.split(","):
        world, seed = run.rsplit(":", 1)
        for t, k, a, b, truth in _pairs(world, int(seed), step):
            fast, t_fast = _match(a, b, search, images)
            fine, t_fine = _match(a, b, search_fine, images)
            if fast is None or fine is None:
                continue
            d = fast.pose - fine.pose
            row = {
                "world": world,
                "seed": int(seed),
                "t_s": t,
                "robot": f"r{k + 1}",
                "coarse_to_fine_s": t_fast,
                "fine_s": t_fine,
                "same_verdict": fast.accepted == fine.accepted
                and fast.proposed == fine.proposed
                and fast.reason.split(":")[0] == fine.reason.split(":")[0],
                "same_pose": bool(np.hypot(d[0], d[1]) < 0.05 and abs(wrap(d[2])) < 1e-3),
                "fine_accepted_or_proposed": bool(fine.proposed),
                # each pose against the true frame (metres, degrees), and each verdict
                "coarse_to_fine": _scored(fast, truth),
                "fine": _scored(fine, truth),
            }
            rows.append(row)
            print(json.dumps(row), flush=True)
    by_world: dict = {}
    for world in dict.fromkeys(r["world"] for r in rows):
        w = [r for r in rows if r["world"] == world]
        by_world[world] = {
            "pairs": len(w),
            "coarse_to_fine_s_median": statistics.median(r["coarse_to_fine_s"] for r in w),
            "fine_s_median": statistics.median(r["fine_s"] for r in w),
            "speedup_median": statistics.median(r["fine_s"] / r["coarse_to_fine_s"] for r in w),
        }
    proposed = [r for r in rows if r["fine_accepted_or_proposed"]]
    version = subprocess.run(
        ["git", "describe", "--always", "--dirty"], check=False, capture_output=True, text=True
    ).stdout.strip()
    result = {
        "command": "python examples/map_search_side_by_side.py " + " ".join(sys.argv[1:]),
        "code_version": version,
        "images_checked": images,
        "pairs": len(rows),
        "same_verdict": sum(r["same_verdict"] for r in rows),
        "accepted_or_proposed": len(proposed),
        "same_pose_where_accepted_or_proposed": sum(r["same_pose"] for r in proposed),
        "wrong_proposed_coarse_to_fine": sum(_wrong(r["coarse_to_fine"]) for r in rows),
        "wrong_proposed_fine": sum(_wrong(r["fine"]) for r in rows),
        "worlds": by_world,
        "rows": rows,
    }
    Path(out).write_text(json.dumps(result, indent=1))
    print(json.dumps({k: v for k, v in result.items() if k != "rows"}, indent=1))


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a != "--images"]
    if len(args) < 2:
        sys.exit(__doc__)
    main(args[0], args[1], int(args[2]) if len(args) > 2 else 3, "--images" in sys.argv)
