"""Trajectory accuracy (pure functions, no I/O).

ate_rmse(est, ref)                 absolute trajectory error after SE(2) alignment
rpe(est, ref, 1.0)                 relative pose error over 1 m of travel
max_errors(est, ref)               largest translation / rotation error (same frame)
"""

from __future__ import annotations

import math

import numpy as np

from polyswarm.se2 import relative_many, wrap


def align_se2(est_xy: np.ndarray, ref_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R and translation t minimising |R est + t - ref| (no scale)."""
    me, mr = est_xy.mean(axis=0), ref_xy.mean(axis=0)
    H = (est_xy - me).T @ (ref_xy - mr)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, mr - R @ me


def ate_rmse(est: np.ndarray, ref: np.ndarray, align: bool = True) -> float:
    e, r = np.asarray(est)[:, :2], np.asarray(ref)[:, :2]
    if align and len(e) >= 2:
        R, t = align_se2(e, r)
        e = e @ R.T + t
    return float(np.sqrt(np.mean(np.sum((e - r) ** 2, axis=1))))


def travelled(ref: np.ndarray) -> np.ndarray:
    """Cumulative distance along a trajectory."""
    step = np.hypot(*np.diff(np.asarray(ref)[:, :2], axis=0).T)
    return np.concatenate([[0.0], np.cumsum(step)])


def rpe(est: np.ndarray, ref: np.ndarray, delta_m: float) -> dict:
    """Relative pose error over pose pairs ``delta_m`` of reference travel apart."""
    cum = travelled(ref)
    i = np.arange(len(cum))
    j = np.searchsorted(cum, cum + delta_m)
    ok = j < len(cum)
    i, j = i[ok], j[ok]
    if len(i) == 0:
        return {
            "trans_mean_m": math.nan,
            "trans_std_m": math.nan,
            "rot_mean_deg": math.nan,
            "rot_std_deg": math.nan,
            "pairs": 0,
        }
    dr = relative_many(ref[i], ref[j])
    de = relative_many(est[i], est[j])
    err = relative_many(dr, de)
    t = np.hypot(err[:, 0], err[:, 1])
    r = np.degrees(np.abs(err[:, 2]))
    return {
        "trans_mean_m": float(t.mean()),
        "trans_std_m": float(t.std()),
        "rot_mean_deg": float(r.mean()),
        "rot_std_deg": float(r.std()),
        "pairs": len(i),
    }


def max_errors(est: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """Largest translational (m) and rotational (deg) error, frames as given."""
    est, ref = np.asarray(est), np.asarray(ref)
    t = np.hypot(est[:, 0] - ref[:, 0], est[:, 1] - ref[:, 1])
    r = np.degrees(np.abs(wrap(est[:, 2] - ref[:, 2])))
    return float(t.max()), float(r.max())
