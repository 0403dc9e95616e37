"""The evidence behind a robot's map: every scan's beams, counted per 5 cm cell.

A keyframe polygon made from one sweep of a low-cost lidar is a poor witness: such
lidars lose 20-80 % of their beams in runs (dark, shiny and glass surfaces), so a wall
shows as a few scattered returns, and a beam without a return may have crossed free
space or met a black cabinet. So every scan (keyframes and the sweeps between them) is
counted into a grid, as a grid SLAM package counts it:

* a beam with a return: a *miss* in every cell it crossed, a *hit* where it ended
  (strong evidence);
* a beam without a return: a *weak miss* in every cell up to the range a no-return beam
  is trusted to (``slam.no_return_free_m``): weak evidence, outvoted by one hit.

A cell's log-odds is ``HIT * hits + MISS * misses + WEAK_MISS * weak misses``: occupied
above 0, free below 0, unknown when nothing crossed it. A keyframe's polygon is then the
*view* of this evidence from the keyframe's lidar (``view``): along each beam, free
space up to the first cell that is not free; an obstacle where that cell is occupied (or
next to one), a frontier where it is unknown. Sparse returns on one surface, seen by
many sweeps, make an obstacle; a wall seen by several keyframes stops the view where one
keyframe's beams missed it; free space a no-return beam assumed ends at the wall a later
scan saw there.

The counts follow the pose graph: each scan's rays are kept in the frame of the keyframe
it belongs to (``KeyframeRays``), and a keyframe the graph moves is counted out at its
old pose and in at its new one (``move``).

    ev = EvidenceGrid()
    ev.add(rays.placed(pose))           # every scan, at its pose
    ranges, on_obstacle = ev.view(origin, bearings, max_range_m)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from polyswarm.errors import MapError
from polyswarm.se2 import compose, transform_points, wrap
from polyswarm.slam.scan import ScanPoints

RESOLUTION_M = 0.05  # a grid SLAM package's usual cell
HIT = 0.85  # log-odds of a return's end cell (p 0.7; OctoMap's)
MISS = -0.4  # ... of a cell a return's beam crossed (p 0.4)
WEAK_MISS = -0.1  # ... of a cell a beam without a return crossed: one hit outvotes 8
STEP_SHARE = 0.5  # beams are sampled every half cell
GROW_M = 20.0  # the grid grows by at least this much when a ray leaves it
MAX_CELLS = 64_000_000  # a grid larger than this is refused (384 MB of counts)
NEAR_OBSTACLE_CELLS = 1  # a view ending this close to an occupied cell ends on a wall
COUNT_MAX = 32_000  # counts saturate below int16's limit
# a keyframe moved less than half a cell is counted where it was (a turn counts at
# REACH_M metres per radian): the pose graph nudges every keyframe a little at each loop
# closure, and on 5 cm cells a nudge of a centimetre changes next to nothing
MOVE_SHARE = 0.5
REACH_M = 5.0


@dataclass(frozen=True)
class Rays:
    """Beams in one frame: where each starts (the lidar), where it ends, and whether it
    ended on a return (else it is a no-return beam, cut at its trusted range)."""

    origins: np.ndarray  # (n, 2)
    ends: np.ndarray  # (n, 2)
    hit: np.ndarray  # (n,) bool

    def placed(self, pose) -> Rays:
        """These rays (in a robot's frame) in the frame where the robot is at ``pose``."""
        return Rays(
            transform_points(pose, self.origins), transform_points(pose, self.ends), self.hit
        )

    @staticmethod
    def join(parts: list[Rays]) -> Rays:
        if not parts:
            z = np.zeros((0, 2))
            return Rays(z, z, np.zeros(0, dtype=bool))
        return Rays(
            np.concatenate([p.origins for p in parts]),
            np.concatenate([p.ends for p in parts]),
            np.concatenate([p.hit for p in parts]),
        )


class EvidenceGrid:
    """Hit, miss and weak-miss counts per cell, on a grid that grows with the rays."""

    def __init__(self, resolution_m: float = RESOLUTION_M) -> None:
        self.res = float(resolution_m)
        # cell (0, 0) of the array is world cell ``first`` (columns along x, rows along y):
        # a point's cell is floor(x / res) whatever the array's extent, so a grid that
        # grew another way counts the same rays in the same cells
        self.first = np.zeros(2, dtype=np.int64)
        self.counts = np.zeros((3, 0, 0), dtype=np.int16)  # hits, misses, weak misses
        # where in its cell each scan's return fell, summed over the cell's hits (metres
        # from the cell's corner, x and y): the walls' positions finer than a cell
        self.hit_xy = np.zeros((2, 0, 0), dtype=np.float32)

    @property
    def shape(self) -> tuple[int, int]:
        return self.counts.shape[1], self.counts.shape[2]

    def add(self, rays: Rays | list[Rays], sign: int = 1) -> None:
        """Count scans' rays in (``sign`` -1: out again), each ``Rays`` one scan. In one
        scan a cell is counted once per kind, and a cell a return ended in is not also a
        miss."""
        scans = [rays] if isinstance(rays, Rays) else [r for r in rays if len(r.ends)]
        if not scans:
            return
        self._cover(np.vstack([np.vstack([r.origins, r.ends]) for r in scans]))
        rows, cols = self.shape
        size = rows * cols
        kinds = [[], [], []]  # per kind: scan * size + cell, for every scan
        spots = []  # per scan: (its hit cells, where in them its returns fell on average)
        for k, r in enumerate(scans):
            hit, spot = self._hit_spots(r.ends[r.hit])
            spots.append((hit, spot))
            passed = self._passed(r.origins[r.hit], r.ends[r.hit])
            weak = self._passed(r.origins[~r.hit], r.ends[~r.hit], to_end=True)
            passed = np.setdiff1d(passed, hit, assume_unique=True)
            weak = np.setdiff1d(weak, np.union1d(hit, passed), assume_unique=True)
            for kind, cells in zip(kinds, (hit, passed, weak), strict=True):
                kind.append(cells + k * size)
        flat = self.counts.reshape(3, size)
        for k, keyed in enumerate(kinds):
            touched, n = np.unique(np.concatenate(keyed) % size, return_counts=True)
            v = flat[k, touched].astype(np.int32) + sign * n
            flat[k, touched] = np.clip(v, 0, COUNT_MAX).astype(np.int16)
        at = self.hit_xy.reshape(2, size)
        for cells, spot in spots:
            np.add.at(at[0], cells, sign * spot[:, 0])
            np.add.at(at[1], cells, sign * spot[:, 1])
        empty = flat[0] == 0
        at[:, empty] = 0.0  # no hit left: no position (counts out may leave rounding)

    def _hit_spots(self, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The cells the returns ``ends`` fell in (flat, each once) and, per cell, where
        in it they fell on average (metres from its corner)."""
        rows, cols = self.shape
        cx = np.floor(ends[:, 0] / self.res).astype(np.int64)
        cy = np.floor(ends[:, 1] / self.res).astype(np.int64)
        c, r = cx - self.first[0], cy - self.first[1]
        ok = (c >= 0) & (c < cols) & (r >= 0) & (r < rows)
        flat = r[ok] * cols + c[ok]
        off = ends[ok] - np.stack([cx[ok], cy[ok]], axis=1) * self.res
        cells, inv = np.unique(flat, return_inverse=True)
        n = np.bincount(inv, minlength=len(cells))
        spot = (
            np.stack(
                [np.bincount(inv, off[:, 0], len(cells)), np.bincount(inv, off[:, 1], len(cells))],
                axis=1,
            )
            / np.maximum(n, 1)[:, None]
        )
        return cells, spot

    def hit_centroids(self, window: tuple[int, int, int, int]) -> tuple[np.ndarray, np.ndarray]:
        """The occupied cells of ``window`` (mask) and where their returns fell on average
        (world metres, (k, 2) in the mask's row-major order)."""
        i0, i1, j0, j1 = window
        _, occ = self.masks(window)
        h = self.counts[0, i0:i1, j0:j1].astype(np.float32)
        r, c = np.nonzero(occ)
        fj, fi = (int(v) for v in self.first)
        xy = self.hit_xy[:, i0:i1, j0:j1][:, r, c] / np.maximum(h[r, c], 1.0)
        corner = np.stack([(fj + j0 + c) * self.res, (fi + i0 + r) * self.res])
        return occ, (corner + xy).T

    def log_odds(self, window: tuple[int, int, int, int] | None = None) -> np.ndarray:
        """Each cell's log-odds (of the array rows i0:i1, columns j0:j1 of ``window``)."""
        sub = self.counts if window is None else self._sub(window)
        h, m, w = (c.astype(np.float32) for c in sub)
        return HIT * h + MISS * m + WEAK_MISS * w

    def masks(
        self, window: tuple[int, int, int, int] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """(free, occupied) cells (of ``window``); unknown cells are in neither."""
        L = self.log_odds(window)
        seen = (self.counts if window is None else self._sub(window)).any(axis=0)
        return seen & (L < 0), seen & (L > 0)

    def _sub(self, window: tuple[int, int, int, int]) -> np.ndarray:
        i0, i1, j0, j1 = window
        return self.counts[:, i0:i1, j0:j1]

    def view(
        self, origin, bearings: np.ndarray, max_range_m: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Along each bearing (radians) from ``origin``: how far the free space reaches
        (metres; single unknown cells between free ones are bridged: beams fan out at
        range), and whether it ends at an occupied cell or next to one."""
        f, occ, x0, y0 = self._window(np.asarray(origin, dtype=float), max_range_m)
        step = STEP_SHARE * self.res
        ts = np.arange(step, max_range_m + step, step)
        d = np.stack([np.cos(bearings), np.sin(bearings)], axis=1)
        px = origin[0] + ts[None, :] * d[:, :1]
        py = origin[1] + ts[None, :] * d[:, 1:]
        c = np.floor((px - x0) / self.res).astype(np.int64)
        r = np.floor((py - y0) / self.res).astype(np.int64)
        inside = (r >= 0) & (r < f.shape[0]) & (c >= 0) & (c < f.shape[1])
        rc, cc = np.clip(r, 0, f.shape[0] - 1), np.clip(c, 0, f.shape[1] - 1)
        stop = ~(inside & f[rc, cc])
        any_stop = stop.any(axis=1)
        first = np.where(any_stop, stop.argmax(axis=1), len(ts) - 1)
        reach = np.maximum(ts[first] - step, 0.0)
        k = np.arange(len(first))
        on = any_stop & inside[k, first] & occ[rc[k, first], cc[k, first]]
        return reach, on

    def window_around(self, xy, radius_m: float) -> tuple[int, int, int, int]:
        """The array rows i0:i1 and columns j0:j1 of the cells within ``radius_m`` of
        ``xy`` (world metres), clipped to the grid."""
        rows, cols = self.shape
        fj, fi = (int(v) for v in self.first)
        i0 = max(math.floor((xy[1] - radius_m) / self.res) - fi, 0)
        j0 = max(math.floor((xy[0] - radius_m) / self.res) - fj, 0)
        i1 = min(math.ceil((xy[1] + radius_m) / self.res) + 1 - fi, rows)
        j1 = min(math.ceil((xy[0] + radius_m) / self.res) + 1 - fj, cols)
        return i0, i1, j0, j1

    # -- internals ------------------------------------------------------------------------

    def _window(self, origin: np.ndarray, radius_m: float):
        """Free (small unknown gaps bridged) and near-occupied masks of the cells within
        ``radius_m`` of ``origin``, with the window's corner."""
        i0, i1, j0, j1 = self.window_around(origin, radius_m)
        free, occ = self.masks((i0, i1, j0, j1))
        seen = self._sub((i0, i1, j0, j1)).any(axis=0)
        gaps = ~seen & ndimage.binary_closing(free, np.ones((3, 3), dtype=bool))
        near = ndimage.binary_dilation(occ, iterations=NEAR_OBSTACLE_CELLS)
        fj, fi = (int(v) for v in self.first)
        x0 = (fj + j0) * self.res
        y0 = (fi + i0) * self.res
        return free | gaps, near, x0, y0

    def _passed(self, origins: np.ndarray, ends: np.ndarray, to_end: bool = False) -> np.ndarray:
        """Flat indices of the cells the beams cross before their end cell (through it,
        for a no-return beam), each once."""
        if len(ends) == 0:
            return np.zeros(0, dtype=np.int64)
        d = ends - origins
        length = np.hypot(d[:, 0], d[:, 1])
        step = STEP_SHARE * self.res
        n = np.ceil(length / step).astype(np.int64) + (1 if to_end else 0)
        beam = np.repeat(np.arange(len(ends)), n)
        k = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
        t = np.minimum(k * step / np.maximum(length[beam], 1e-12), 1.0)
        return self._flat(origins[beam] + t[:, None] * d[beam])

    def _flat(self, xy: np.ndarray) -> np.ndarray:
        rows, cols = self.shape
        c = np.floor(xy[:, 0] / self.res).astype(np.int64) - self.first[0]
        r = np.floor(xy[:, 1] / self.res).astype(np.int64) - self.first[1]
        ok = (c >= 0) & (c < cols) & (r >= 0) & (r < rows)
        return np.unique(r[ok] * cols + c[ok])

    @property
    def origin(self) -> np.ndarray:
        """World position (metres) of the corner of the array's cell (0, 0)."""
        return self.first * self.res

    def _cover(self, xy: np.ndarray) -> None:
        """Grow the grid so that every point of ``xy`` lies in it."""
        rows, cols = self.shape
        lo = np.floor(xy.min(axis=0) / self.res).astype(np.int64)
        hi = np.floor(xy.max(axis=0) / self.res).astype(np.int64)
        last = self.first + np.array([cols, rows]) - 1
        if rows and (lo >= self.first).all() and (hi <= last).all():
            return
        grow = math.ceil(GROW_M / self.res)
        new_first = np.minimum(self.first, lo - grow) if rows else lo - grow
        new_last = np.maximum(last, hi + grow) if rows else hi + grow
        new_cols, new_rows = (int(v) for v in new_last - new_first + 1)
        if new_rows * new_cols > MAX_CELLS:
            raise MapError(f"an evidence grid of {new_rows} x {new_cols} cells is refused")
        grown = np.zeros((3, new_rows, new_cols), dtype=np.int16)
        spots = np.zeros((2, new_rows, new_cols), dtype=np.float32)
        if rows:
            dj, di = (int(v) for v in self.first - new_first)
            grown[:, di : di + rows, dj : dj + cols] = self.counts
            spots[:, di : di + rows, dj : dj + cols] = self.hit_xy
        self.counts, self.hit_xy, self.first = grown, spots, new_first


class KeyframeRays:
    """Every scan's rays, kept in the frame of the keyframe (pose-graph node) it belongs
    to, and counted into ``grid`` where that keyframe is now."""

    def __init__(self, grid: EvidenceGrid) -> None:
        self.grid = grid
        self.scans: dict[int, list[tuple[np.ndarray, Rays]]] = {}  # node -> (offset, rays)
        self.at: dict[int, np.ndarray] = {}  # node -> the pose its rays are counted at

    def add(self, node: int, node_pose, offset, points: ScanPoints) -> None:
        """A scan taken at ``offset`` from keyframe ``node`` (at ``node_pose``)."""
        rays = scan_rays(points)
        rays = Rays(rays.origins.astype(np.float32), rays.ends.astype(np.float32), rays.hit)
        off = np.asarray(offset, dtype=float)
        self.scans.setdefault(node, []).append((off, rays))
        at = self.at.setdefault(node, np.asarray(node_pose, dtype=float))
        self.grid.add(rays.placed(compose(at, off)))

    def move_to(self, poses) -> int:
        """Count each keyframe's rays again where ``poses[node]`` puts it, if it moved
        more than ``MOVE_SHARE`` of a cell; the keyframes moved."""
        moved = 0
        out: list[Rays] = []  # counted out where they were ...
        back: list[Rays] = []  # ... and in where they are now
        for node, at in self.at.items():
            if node >= len(poses):
                continue
            new = np.asarray(poses[node], dtype=float)
            turn = abs(float(wrap(new[2] - at[2])))
            if math.hypot(*(new[:2] - at[:2])) + REACH_M * turn <= MOVE_SHARE * self.grid.res:
                continue
            out.extend(rays.placed(compose(at, off)) for off, rays in self.scans[node])
            back.extend(rays.placed(compose(new, off)) for off, rays in self.scans[node])
            self.at[node] = new
            moved += 1
        self.grid.add(out, -1)
        self.grid.add(back)
        return moved


def scan_rays(points: ScanPoints) -> Rays:
    """A scan's rays in the robot frame: its returns, and its no-return beams cut where
    free space is trusted to reach (``scan.scan_to_points`` put them there)."""
    ret = points.valid
    weak = points.no_return if points.no_return is not None else np.zeros_like(ret)
    use = ret | weak
    origins = np.broadcast_to(points.origin, (int(use.sum()), 2))
    return Rays(np.array(origins), points.xy[use], ret[use])


def view_points(
    ev: EvidenceGrid,
    points: ScanPoints,
    pose,
    fov_rad: float,
    beams: int,
    max_range_m: float,
    min_range_m: float,
    oversample: int = 2,
) -> ScanPoints:
    """The keyframe's points as the evidence sees them from its lidar (robot frame): one
    ray per ``1 / oversample`` of a beam over the lidar's field of view, each ending where
    the free space ends (at least ``min_range_m`` out), valid where that is on a wall.
    Where the keyframe's own return agrees with the view (within two cells), its point
    is kept: a return is more precise than a cell."""
    full = fov_rad >= 2 * math.pi - 1e-6
    rel = points.xy - points.origin
    n = max(beams * oversample, 8)
    if full:
        b = -math.pi + (np.arange(n) + 0.5) * (2 * math.pi / n)
    else:
        ang = np.arctan2(rel[:, 1], rel[:, 0])
        centre = math.atan2(np.sin(ang).mean(), np.cos(ang).mean())
        b = centre + np.linspace(-fov_rad / 2, fov_rad / 2, n)
    origin_w = transform_points(pose, points.origin[None, :])[0]
    reach, on = ev.view(origin_w, b + float(pose[2]), max_range_m)
    reach = np.maximum(reach, min_range_m)
    on &= reach > min_range_m
    xy = points.origin + reach[:, None] * np.stack([np.cos(b), np.sin(b)], axis=1)
    own = points.valid & (np.hypot(rel[:, 0], rel[:, 1]) > 0)
    if own.any():
        xy = _own_returns(xy, on, reach, b, rel[own], points.xy[own], n, full, fov_rad, ev.res)
    return ScanPoints(xy, on, full, points.origin)


def _own_returns(xy, on, reach, b, rel, own_xy, n: int, full: bool, fov: float, res: float):
    """``xy`` with each view ray that ends on a wall replaced by the keyframe's own return
    along it, where that return lies within two cells of the view's end."""
    pa = np.arctan2(rel[:, 1], rel[:, 0])
    pr = np.hypot(rel[:, 0], rel[:, 1])
    order = np.argsort(pa)
    pa, pr, pxy = pa[order], pr[order], own_xy[order]
    wrapped = np.arctan2(np.sin(b), np.cos(b))
    k = np.clip(np.searchsorted(pa, wrapped), 0, len(pa) - 1)
    k0 = np.clip(k - 1, 0, len(pa) - 1)

    def off(j):  # angle between return j and the ray
        return np.abs(np.arctan2(np.sin(pa[j] - wrapped), np.cos(pa[j] - wrapped)))

    k = np.where(off(k0) < off(k), k0, k)
    half = math.pi / n if full else fov / (2 * max(n - 1, 1))
    agree = on & (off(k) <= half) & (np.abs(pr[k] - reach) <= 2 * res)
    out = xy.copy()
    out[agree] = pxy[k[agree]]
    return out
