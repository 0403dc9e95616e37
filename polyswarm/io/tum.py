"""TUM trajectories: ``t x y z qx qy qz qw`` per line (readable by evo)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from polyswarm.errors import DataFormatError


def write_tum(path: str | Path, stamps: np.ndarray, poses: np.ndarray) -> None:
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    half = poses[:, 2] / 2
    rows = np.column_stack(
        [
            stamps,
            poses[:, 0],
            poses[:, 1],
            np.zeros(len(poses)),
            np.zeros(len(poses)),
            np.zeros(len(poses)),
            np.sin(half),
            np.cos(half),
        ]
    )
    np.savetxt(path, rows, fmt="%.6f", header="t x y z qx qy qz qw", comments="# ")


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Stamps and (x, y, yaw) poses of a TUM file."""
    try:
        d = np.loadtxt(path, comments="#", ndmin=2)
    except (OSError, ValueError) as e:
        raise DataFormatError(f"{path}: not a TUM trajectory: {e}") from e
    if d.shape[1] != 8:
        raise DataFormatError(f"{path}: TUM lines need 8 values, got {d.shape[1]}")
    yaw = 2 * np.arctan2(d[:, 6], d[:, 7])
    return d[:, 0], np.column_stack([d[:, 1], d[:, 2], yaw])
