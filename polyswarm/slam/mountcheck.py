"""Is the lidar mount right? A wrong mount smears the map: the same wall, seen from poses
the odometry gives, lands in many places. So the scans are placed at their odometry
poses with the mount as given, turned by pi, and mirrored (upside down), and the
occupied 5 cm cells of each are counted (``evaluation.maps.occupied_cells``): the mount
whose map is sharpest fills the fewest.

    check = check_mount(scans, odometry_poses, (x, y, yaw, upside_down))
    if check.better: log.warning(check.advice)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from polyswarm.evaluation.maps import occupied_cells
from polyswarm.slam.scan import LaserScan

SHARPER = 0.85  # another mount is named when its map fills at most this share of the cells
MAX_SCANS = 400  # scans taken, evenly spread over the recording: enough to see a smear


@dataclass(frozen=True)
class MountCheck:
    cells: dict[str, int]  # occupied 5 cm cells: "as given", "turned by pi", "mirrored"
    turned_rad: float  # how far the robot turned over the scans checked
    better: str = ""  # the alternative whose map is sharpest, when it is SHARPER

    @property
    def advice(self) -> str:
        if not self.better:
            return ""
        mine, theirs = self.cells["as given"], self.cells[self.better]
        return (
            f"the scans line up far better with the lidar {self.better} ({theirs} occupied "
            f"5 cm cells against {mine} as given): check the mount"
        )


def check_mount(
    scans: list[LaserScan], poses: np.ndarray, mount: tuple[float, float, float, bool]
) -> MountCheck:
    """Compare the sharpness of the scans' map (at odometry ``poses``) for ``mount`` and
    for the lidar turned by pi and mirrored."""
    n = len(scans)
    pick = np.unique(np.linspace(0, n - 1, min(n, MAX_SCANS)).round().astype(int)) if n else []
    sub = [scans[k] for k in pick]
    at = np.asarray(poses, dtype=float)[pick] if n else np.zeros((0, 3))
    turned = float(np.abs(np.diff(np.unwrap(at[:, 2]))).sum()) if len(at) > 1 else 0.0
    x, y, yaw, flip = mount
    candidates = {
        "as given": mount,
        "turned by pi": (x, y, yaw + math.pi, flip),
        "mirrored": (x, y, yaw, not flip),
    }
    cells = {name: occupied_cells(sub, at, m) for name, m in candidates.items()}
    best = min(cells, key=cells.get)
    better = ""
    if best != "as given" and cells[best] <= SHARPER * cells["as given"]:
        better = best
    return MountCheck(cells, turned, better)
