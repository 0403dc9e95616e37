"""Obstacles the robot's lidar sees that the map it plans on does not hold.

The merged map can lack a wall: two robots' maps, each a few centimetres off, both put
free space into a thin wall from either side, and their union cuts through it (a
TurtleBot3's 3.5 m lidar with 2-6 cm of noise on the office). A planner that trusts the
map then sends the robot into the wall, its local controller stops it short, and it
stays stuck there. Like the obstacle layer of a navigation stack's global costmap,
``SeenObstacles`` remembers for a while the returns close to the robot that the planning
map does not explain, and the planner keeps its distance from them as from walls.
Other robots' returns are left out by the caller where it knows where they are (they
move); a remembered point a later scan sees through is forgotten, as a costmap's
obstacle layer clears along its rays: a robot whose frame is not known yet that stood
beside a door, a person gone by. (Remembered 60 s, two waiting robots that came to see
the first at a door of the rooms world walled it in: no path from where it stood, and
the mission ended at 76 % coverage; launch at unknown starts, seed 0.)
"""

from __future__ import annotations

import numpy as np

from polyswarm.nav.navgraph import clear_of
from polyswarm.nav.recent import seen_through
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

    def forget_seen_through(self, world_xy: np.ndarray, robot_xy) -> int:
        """Forget the remembered points a scan sees through: ``world_xy`` (n, 2) every
        return of the scan (world frame, other robots' too: they hide what is behind
        them), seen from ``robot_xy`` (``polyswarm.nav.recent.seen_through``). Returns
        how many were forgotten."""
        if not self._points:
            return 0
        keys = list(self._points)
        mem = np.array([self._points[k][:2] for k in keys])
        through = seen_through(mem, world_xy, robot_xy)
        for k in np.flatnonzero(through):
            del self._points[keys[k]]
        return int(through.sum())

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
