"""How far each robot's own pose estimate was from the truth, over a `launch` run.

    python examples/robot_drift.py runs/<launch>

Reads ``trajectories/rK.tum`` (the robot's SLAM estimate, in the shared frame its
start pose defines) and ``rK_truth.tum`` (the simulator's ground truth), matches each
estimate to the first true pose at or after its time, and prints per robot the largest
and final position error and the error along the run (no alignment: the start pose is
known).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from polyswarm.io.tum import read_tum


def main(run: str, rows: str = "12") -> None:
    for est_path in sorted(Path(run).glob("trajectories/r*.tum")):
        if est_path.stem.endswith("_truth"):
            continue
        t_est, est = read_tum(est_path)
        t_true, true = read_tum(est_path.with_name(f"{est_path.stem}_truth.tum"))
        k = np.searchsorted(t_true, t_est).clip(0, len(t_true) - 1)
        d = est[:, :2] - true[k, :2]
        err = np.hypot(d[:, 0], d[:, 1])
        path = np.r_[0.0, np.cumsum(np.hypot(*np.diff(true[:, :2], axis=0).T))][k]
        print(f"{est_path.stem}: largest error {err.max():.2f} m, final {err[-1]:.2f} m")
        for q in np.linspace(0, len(err) - 1, int(rows)).astype(int):
            print(
                f"  t {t_est[q]:7.1f} s  path {path[q]:6.1f} m  "
                f"error x {d[q, 0]:+.2f} m, y {d[q, 1]:+.2f} m"
            )


if __name__ == "__main__":
    main(*sys.argv[1:])
