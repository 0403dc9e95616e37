"""Coverage routes on a world's ground truth, and a pure-pursuit follower.

Used to collect data for single-robot SLAM runs (the thesis' Table 5.1 experiment):
the robot visits one waypoint per ``spacing_m`` block of free space, nearest first
by path length, driving on a grid kept ``clearance_m`` away from walls. Control uses
the true pose (as a teleoperator would); the SLAM only gets the noisy odometry.

    route = coverage_route(world)            # (n, 2) polyline, metres
    follower = PurePursuit(route)
    v, w = follower.command(true_pose)
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from polyswarm.errors import SimulationError
from sim.world import World

FINE_GRID_M = 0.1  # planning grid for small worlds (0.9 m doors need it)
COARSE_GRID_M = 0.25  # planning grid for large worlds (keeps Dijkstra fast)
LARGE_WORLD_M2 = 1500.0


def _free_grid(world: World, res: float):
    x0, y0, x1, y1 = world.free.bounds
    cols, rows = math.ceil((x1 - x0) / res), math.ceil((y1 - y0) / res)
    xs = x0 + (np.arange(cols) + 0.5) * res
    ys = y0 + (np.arange(rows) + 0.5) * res
    X, Y = np.meshgrid(xs, ys)
    shapely.prepare(world.free)
    free = shapely.contains_xy(world.free, X, Y)
    return free, (x0, y0)


def coverage_route(
    world: World, spacing_m: float = 4.0, clearance_m: float = 0.3, start=None
) -> np.ndarray:
    res = COARSE_GRID_M if world.free.area > LARGE_WORLD_M2 else FINE_GRID_M
    free, (ox, oy) = _free_grid(world, res)
    # pad with non-free cells (the outer walls lie just outside the grid); a cell-centre
    # distance can overstate the true clearance by half a cell diagonal
    clear = ndimage.distance_transform_edt(np.pad(free, 1))[1:-1, 1:-1] * res
    safe = clear - res * 0.71 >= clearance_m
    # a wall thinner than a cell can fall between cell centres, so that the grid sees
    # free cells on both sides and routes through it: measure to the true walls too
    r, c = np.nonzero(safe)
    starts, ends = world.wall_segments
    walls = shapely.STRtree(shapely.linestrings(np.stack([starts, ends], axis=1)))
    centres = shapely.points(ox + (c + 0.5) * res, oy + (r + 0.5) * res)
    _, d = walls.query_nearest(centres, return_distance=True, all_matches=False)
    safe[r, c] = d >= clearance_m
    clear[r, c] = np.minimum(clear[r, c], d)
    rows, cols = safe.shape
    idx = -np.ones(safe.shape, dtype=np.int64)
    cells = np.argwhere(safe)
    idx[safe] = np.arange(len(cells))
    # 8-connected grid graph over safe cells, edge length in metres
    src, dst, wts = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        r2, c2 = cells[:, 0] + dr, cells[:, 1] + dc
        ok = (r2 >= 0) & (r2 < rows) & (c2 >= 0) & (c2 < cols)
        a, r2, c2 = np.nonzero(ok)[0], r2[ok], c2[ok]
        b = idx[r2, c2]
        good = b >= 0
        src.append(a[good])
        dst.append(b[good])
        wts.append(np.full(good.sum(), res * math.hypot(dr, dc)))
    src, dst, wts = np.concatenate(src), np.concatenate(dst), np.concatenate(wts)
    graph = coo_matrix(
        (np.r_[wts, wts], (np.r_[src, dst], np.r_[dst, src])), shape=(len(cells),) * 2
    ).tocsr()
    sx, sy = world.start if start is None else start
    here = _nearest_cell(cells, ox, oy, sx, sy, res)
    dist0 = dijkstra(graph, indices=here)
    reach = np.isfinite(dist0)
    # one waypoint per block: the reachable cell with the most clearance
    block = (cells[:, 0] * res // spacing_m).astype(int) * 100_000 + (
        cells[:, 1] * res // spacing_m
    ).astype(int)
    targets = []
    for b in np.unique(block[reach]):
        m = np.nonzero((block == b) & reach)[0]
        targets.append(int(m[np.argmax(clear[cells[m, 0], cells[m, 1]])]))
    todo = set(targets)
    path = [here]
    while todo:
        dist, pred = dijkstra(graph, indices=here, return_predecessors=True)
        nxt = min(todo, key=lambda t: dist[t])
        if not np.isfinite(dist[nxt]):
            break
        seg = []
        k = nxt
        while k != here:
            seg.append(k)
            k = pred[k]
        path += seg[::-1]
        todo.discard(nxt)
        here = nxt
        todo -= {t for t in todo if dist[t] < 1e-9}
    pts = np.stack([ox + (cells[path, 1] + 0.5) * res, oy + (cells[path, 0] + 0.5) * res], axis=1)
    if len(pts) < 2:
        raise SimulationError(f"no route through world {world.name!r}")
    line = shapely.LineString(pts).simplify(res * 0.5)
    return np.asarray(line.coords)


def _nearest_cell(cells, ox, oy, x, y, res: float) -> int:
    cx = ox + (cells[:, 1] + 0.5) * res
    cy = oy + (cells[:, 0] + 0.5) * res
    return int(np.argmin((cx - x) ** 2 + (cy - y) ** 2))


def route_length(route: np.ndarray) -> float:
    return float(np.hypot(*np.diff(route, axis=0).T).sum())


class PurePursuit:
    """Follow a polyline; turn on the spot when the target is behind."""

    def __init__(self, route: np.ndarray, speed: float = 0.5, lookahead: float = 0.5) -> None:
        self.route = np.asarray(route, dtype=float)
        self.speed, self.lookahead = speed, lookahead
        seg = np.diff(self.route, axis=0)
        self.cum = np.concatenate([[0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))])
        self.progress = 0.0  # metres along the route reached so far

    @property
    def done(self) -> bool:
        return self.progress >= self.cum[-1] - 0.05

    def _points_at(self, s) -> np.ndarray:
        s = np.clip(s, 0.0, self.cum[-1])
        return np.stack(
            [np.interp(s, self.cum, self.route[:, 0]), np.interp(s, self.cum, self.route[:, 1])],
            axis=-1,
        )

    def command(self, pose) -> tuple[float, float]:
        x, y, th = pose
        # advance progress to the closest route point within a short window ahead
        window = np.linspace(self.progress, min(self.progress + 2.0, self.cum[-1]), 41)
        pts = self._points_at(window)
        self.progress = float(window[np.argmin(np.hypot(pts[:, 0] - x, pts[:, 1] - y))])
        if self.done:
            return 0.0, 0.0
        tx, ty = self._points_at(self.progress + self.lookahead)
        alpha = math.atan2(ty - y, tx - x) - th
        alpha = (alpha + math.pi) % (2 * math.pi) - math.pi
        if abs(alpha) > math.radians(50):
            return 0.0, math.copysign(1.2, alpha)
        v = self.speed * max(0.3, math.cos(alpha))
        return v, 2.0 * v * math.sin(alpha) / self.lookahead
