"""Obstacles the robot's lidar sees that the map it plans on does not hold.

The merged map can lack a wall: two robots' maps, each a few centimetres off, both put
free space into a thin wall from either side, and their union cuts through it (a
TurtleBot3's 3.5 m lidar with 2-6 cm of noise on the office). A planner that trusts the
map then sends the robot into the wall, its local controller stops it short, and it
stays stuck there. Like the obstacle layer of a navigation stack's global costmap,
``SeenObstacles`` remembers for a while the returns close to the robot that the planning
map does not explain, and the planner keeps its distance from them as from walls.
Other robots' returns are left out by the caller (they move).
"""

from __future__ import annotations

import numpy as np

from polyswarm.navgraph import clear_of
from polyswarm.polymap import GridPolyMap, VectorType

SEEN_RANGE_M = 1.5  # returns this close are remembered (where the robot is about to drive)
# a return this far from every obstacle vector of the planning map is not on a mapped wall
# (more than the map's wall error, bench slam: 3-8 cm)
UNMAPPED_M = 0.15
SEEN_KEEP_S = 60.0  # remembered this long (a door may open, a person walk on)
SEEN_VOXEL_M = 0.05  # one point kept per square this wide
SEEN_MAX = 2000  # points kept at most (the oldest go first)


class SeenObstacles:
    def __init__(self) -> None:
        self._points: dict[tuple[int, int], tuple[float, float, float]] = {}  # key: x, y, t

    def __len__(self) -> int:
        return len(self._points)

    def add(self, now_s: float, world_xy: np.ndarray, robot_xy, pmap: GridPolyMap) -> int:
        """Remember the returns (world frame) within ``SEEN_RANGE_M`` of the robot that
        ``pmap`` does not explain; forget those older than ``SEEN_KEEP_S``. Returns how
        many were added."""
        self._expire(now_s)
        pts = np.asarray(world_xy, dtype=float).reshape(-1, 2)
        pts = pts[np.hypot(*(pts - np.asarray(robot_xy)[:2]).T) <= SEEN_RANGE_M]
        if not len(pts):
            return 0
        cells = pmap.cells_within(float(robot_xy[0]), float(robot_xy[1]), SEEN_RANGE_M + 1.0)
        st, en, _ = pmap.vectors([VectorType.OBSTACLE], cells)
        pts = pts[clear_of(pts, st, en, UNMAPPED_M)]
        for x, y in pts:
            key = (int(np.floor(x / SEEN_VOXEL_M)), int(np.floor(y / SEEN_VOXEL_M)))
            self._points.pop(key, None)  # re-inserted: the newest last
            self._points[key] = (float(x), float(y), now_s)
        while len(self._points) > SEEN_MAX:
            self._points.pop(next(iter(self._points)))
        return len(pts)

    def points(self, now_s: float) -> np.ndarray:
        """The remembered points, (k, 2) in the world frame."""
        self._expire(now_s)
        if not self._points:
            return np.zeros((0, 2))
        return np.array([(x, y) for x, y, _ in self._points.values()])

    def _expire(self, now_s: float) -> None:
        old = [k for k, (_, _, t) in self._points.items() if now_s - t > SEEN_KEEP_S]
        for k in old:
            del self._points[k]
