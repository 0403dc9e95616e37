"""Where a run's robots spend their time, from their true trajectories.

    python examples/trajectory_speeds.py runs/bench-thesis/thesis-office-3-hungarian-0
    python examples/trajectory_speeds.py --json RUN_FOLDERS   # time parked only, as JSON

Shares of time standing, turning in place, driving below 80 % of the top speed seen
(the 99th percentile) and at it; over all robots of the run folder(s). And each robot's
time *parked* before the run reached 99 % (its ``t99_s``): windows of ``PARKED_WINDOW_S``
in which it drove less than ``PARKED_M`` (a robot the coordinator gave nothing to do,
or one stuck).
"""

from __future__ import annotations

import glob
import json
import sys
from pathlib import Path

import numpy as np

from polyswarm.io.tum import read_tum

STILL_MPS = 0.03  # slower than this is not driving
STILL_RADPS = 0.1  # ... and turning slower than this is standing
PARKED_WINDOW_S = 10.0  # simulated seconds; a look turn or a replan is shorter
PARKED_M = 0.3  # driven in a window, at most: parked


def shares(run: str) -> tuple[float, dict[str, float]]:
    total = {"standing": 0.0, "turning": 0.0, "slow": 0.0, "fast": 0.0}
    top = 0.0
    for path in sorted(glob.glob(f"{run}/trajectories/*_truth.tum")):
        t, pose = read_tum(path)
        dt = np.diff(t)
        ok = dt > 0
        v = np.hypot(*np.diff(pose[:, :2], axis=0).T)[ok] / dt[ok]
        w = np.abs(np.diff(np.unwrap(pose[:, 2])))[ok] / dt[ok]
        dt = dt[ok]
        top = max(top, float(np.percentile(v, 99)))
        standing = (v < STILL_MPS) & (w < STILL_RADPS)
        turning = (v < STILL_MPS) & ~standing
        slow = (v >= STILL_MPS) & (v < 0.8 * top)
        for k, m in (("standing", standing), ("turning", turning), ("slow", slow)):
            total[k] += float(dt[m].sum())
        total["fast"] += float(dt[v >= 0.8 * top].sum())
    whole = sum(total.values())
    return top, {k: v / whole for k, v in total.items()}


def parked_s(run: str) -> dict[str, float]:
    """Robot id -> simulated seconds parked before the run's t99 (or its end)."""
    metrics = json.loads((Path(run) / "metrics.json").read_text())
    end = metrics.get("t99_s") or metrics["sim_time_s"]
    out = {}
    for path in sorted(glob.glob(f"{run}/trajectories/*_truth.tum")):
        t, pose = read_tum(path)
        parked = 0.0
        for a in np.arange(0.0, end, PARKED_WINDOW_S):
            m = (t >= a) & (t < a + PARKED_WINDOW_S)
            if m.sum() >= 2 and np.hypot(*np.diff(pose[m, :2], axis=0).T).sum() < PARKED_M:
                parked += PARKED_WINDOW_S
        out[Path(path).name.removesuffix("_truth.tum")] = parked
    return out


if __name__ == "__main__":
    if sys.argv[1:2] == ["--json"]:  # robot-seconds parked per run folder, for a result file
        print(json.dumps({Path(r).name: parked_s(r) for r in sys.argv[2:]}, indent=1))
        sys.exit()
    for run in sys.argv[1:]:
        top, s = shares(run)
        print(run, f"top {top:.2f} m/s", ", ".join(f"{k} {v:.0%}" for k, v in s.items()))
        parked = parked_s(run)
        print(f"  parked before t99: {sum(parked.values()):.0f} s", parked)
