"""Only what a keyframe changes: a keyframe polygon with the stretches that cannot change
the map replaced by straight chords, before it is merged and sent.

Most of a keyframe re-observes what the map already holds: walls it has mapped (the
keyframe's obstacle vectors lie within noise of the map's) and space it has explored
(the keyframe's vectors lie inside the map). Merging such a stretch changes nothing: it
is inside the union, or outside it by less than ``min_growth_m``, which the merge
ignores (``MergeOptions``). So a chain of the keyframe's vertices whose vectors, and the
chord that replaces them, all lie in that zone can be dropped; a chord is a frontier
vector (inside the map it vanishes in the union, outside it is a sliver the merge
ignores). On the shared logs a robot then sends 8-17 % fewer bytes (``polyswarm bench
bandwidth``), and the map it builds is the same: explored-area IoU 0.9995-0.9998 with
the untrimmed run, frontier length within 0.1 %.

The robot merges the trimmed polygon itself, so the receiver's replay stays bit-exact;
what the trimming must keep is the map's meaning, hence the zone (for a point ``p``):

* a dropped obstacle vector: ``p`` inside the explored space or within ``band`` of a
  mapped obstacle vector, and farther than ``reach`` from a mapped frontier vector (an
  obstacle beside a frontier turns it into a wall, so those are never dropped);
* a dropped frontier vector, and a chord: ``p`` inside the explored space or within ``band`` of a
  mapped obstacle or frontier vector;
* and between a dropped chain and its chord: no mapped obstacle or frontier vector
  farther than ``band`` inside. The explored space has holes (a pillar the robot drove
  round): a chain along a pillar's face and a chord behind it both lie in explored space,
  and the chord would merge the pillar as explored (a TurtleBot3 in the office world lost
  its corridor pillar and wall ends so; the map matcher then found walls in its clear
  space and refused the right frame).

``band`` is ``BAND_SHARE`` of ``min_growth_m`` (0 when the option is off: only chains
inside the explored space go), and only in cells the map has explored (the merge keeps
growth into a new cell however thin; a property test found that case); ``reach`` is
the largest snapping distance of the options.
The keyframe store keeps the untrimmed polygon for ICP; only the map gets the trimmed one.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from polyswarm.errors import PolyswarmError
from polyswarm.polymap import GridPolyMap, MergeOptions, Ring, TypedPolygon, VectorType
from polyswarm.polymap.rings import OBSTACLE

BAND_SHARE = 0.8  # of min_growth_m: a sliver thinner than min_growth_m is not merged
SAMPLE_SHARE = 1.0  # chords are checked at points this share of the band apart
MIN_SAMPLE_M = 0.01  # ... and never closer than 1 cm (band 0: the interior test alone)
MAX_REPAIRS = 4  # rounds of undoing chords that cross the ring, before giving up
# vectors longer than this are not checked (their ends stay): most are frontiers into the
# unknown, and sampling them took half the trimming's time on 720-beam scans (a
# profiling run of the zigzag route: p95 19 -> 11 ms; csail keeps 0.86 of its vertices
# instead of 0.81; bench slam's merge-stage p95 on 720-beam scans is 29.4 ms with it)
MAX_EDGE_M = 4.0


class _Zone:
    """Which points a dropped chain or its chord may pass through (see module doc)."""

    def __init__(self, pmap: GridPolyMap, bounds, options: MergeOptions) -> None:
        self.band = BAND_SHARE * options.min_growth_m
        self.reach = max(
            options.obstacle_snap_m,
            options.obstacle_snap_behind_m,
            options.obstacle_snap_front_m,
            self.band,
        )
        s = pmap.cell_size
        pad = self.reach + self.band  # the zone is asked about points of the polygon only
        x0, y0, x1, y1 = bounds
        i0, j0 = pmap.cell_index(x0 - pad, y0 - pad)
        i1, j1 = pmap.cell_index(x1 + pad, y1 + pad)
        self.cells = {}
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                c = pmap.cells.get((i, j))
                if c is not None and c.polygons:
                    self.cells[(i, j)] = c
        self.cell_size = s
        self._explored_keys = np.array([i * (1 << 32) + j for i, j in self.cells], np.int64)
        obst = [c.obstacle_vectors for c in self.cells.values()]
        front = [c.frontier_vectors for c in self.cells.values()]
        self.obstacles = _lines(obst)
        self.frontiers = _lines(front)
        self.step = max(SAMPLE_SHARE * self.band, MIN_SAMPLE_M)

    @property
    def empty(self) -> bool:
        return not self.cells

    def inside(self, pts: np.ndarray, geo: np.ndarray) -> np.ndarray:
        idx = np.floor(pts / self.cell_size).astype(np.int64)
        key = idx[:, 0] * (1 << 32) + idx[:, 1]
        order = np.argsort(key, kind="stable")
        bounds = np.flatnonzero(np.diff(key[order])) + 1
        out = np.zeros(len(pts), bool)
        for group in np.split(order, bounds):
            cell = self.cells.get((int(idx[group[0], 0]), int(idx[group[0], 1])))
            if cell is not None:
                out[group] = shapely.covers(cell.region, geo[group])
        return out

    def in_explored_cell(self, pts: np.ndarray) -> np.ndarray:
        idx = np.floor(pts / self.cell_size).astype(np.int64)
        return np.isin(idx[:, 0] * (1 << 32) + idx[:, 1], self._explored_keys)

    def allows(self, pts: np.ndarray, obstacle: bool) -> np.ndarray:
        pts = np.asarray(pts, float).reshape(-1, 2)
        if not len(pts):
            return np.zeros(0, bool)
        geo = shapely.points(pts)
        ok = self.inside(pts, geo)
        if self.band > 0 and not ok.all():
            # the merge ignores thin growth only in cells it has explored: growth into a
            # new cell is kept however thin, so the band stops at explored cells
            rest = ~ok & self.in_explored_cell(pts)
            near = _within(self.obstacles, geo[rest], self.band)
            if not obstacle:
                near |= _within(self.frontiers, geo[rest], self.band)
            ok[rest] = near
        if obstacle and ok.any():
            ok[ok] = ~_within(self.frontiers, geo[ok], self.reach)
        return ok

    def allows_segment(self, a: np.ndarray, b: np.ndarray, obstacle: bool) -> bool:
        n = max(2, math.ceil(float(np.hypot(*(b - a))) / self.step) + 1)
        t = np.linspace(0.0, 1.0, n)[:, None]
        return bool(self.allows(a + t * (b - a), obstacle).all())


def _lines(parts: list[tuple[np.ndarray, np.ndarray]]):
    starts = [s for s, _ in parts if len(s)]
    if not starts:
        return None
    s = np.concatenate(starts)
    e = np.concatenate([e for _, e in parts if len(e)])
    geom = shapely.multilinestrings(shapely.linestrings(np.stack([s, e], axis=1)))
    shapely.prepare(geom)
    return geom


def _within(lines, pts, dist: float) -> np.ndarray:
    if lines is None or dist <= 0:
        return np.zeros(len(pts), bool)
    return shapely.dwithin(lines, pts, dist)


def trim_keyframe(polygon: TypedPolygon, pmap: GridPolyMap, options: MergeOptions) -> TypedPolygon:
    """``polygon`` with the chains that cannot change ``pmap`` replaced by chords; the
    polygon itself when nothing can be dropped or the result would not be valid."""
    xy = polygon.shell.xy
    zone = _Zone(pmap, (*xy.min(axis=0), *xy.max(axis=0)), options)
    if zone.empty:
        return polygon
    rings = [_trim_ring(r, zone) for r in polygon.rings()]
    if all(r is old for r, old in zip(rings, polygon.rings(), strict=True)):
        return polygon
    out = TypedPolygon(rings[0], tuple(rings[1:]))
    try:
        out.validate()
    except PolyswarmError:
        return polygon
    return out


def _trim_ring(ring: Ring, zone: _Zone) -> Ring:
    xy, ty = ring.xy, ring.types
    n = len(xy)
    is_obst = ty == OBSTACLE
    # a vertex may go when it and the vectors on both of its sides lie in the zone
    around_obst = is_obst | np.roll(is_obst, 1)
    droppable = zone.allows(xy, obstacle=False)
    if droppable.sum() < 3:
        return ring
    droppable[droppable & around_obst] = zone.allows(xy[droppable & around_obst], obstacle=True)
    if droppable.sum() < 3:
        return ring
    # ... and the vectors on both sides of it, checked only where that can matter
    need = droppable | np.roll(droppable, -1)
    edge_ok = np.zeros(n, bool)
    edge_ok[need] = _edges_allowed(xy, is_obst, zone, np.flatnonzero(need))
    droppable &= edge_ok & np.roll(edge_ok, 1)
    if droppable.sum() < 3:
        return ring
    chords = []  # (k, j): vertices k+1..j-1 (mod n) dropped, vector k is the chord
    for r0, r1 in _runs(droppable):
        # within a run, chords from one kept vertex to the farthest the zone allows; the
        # run's ends stay, so every dropped vector and every chord lies in the zone
        k = r0
        while k < r1:
            j = _farthest_chord(xy, n, k, r1, zone)
            if j > k + 1:
                chords.append((k, j))
            k = j
    swallowing = _swallowing_chords(xy, chords, zone)
    chords = [c for c in chords if c not in swallowing]
    for _ in range(MAX_REPAIRS):
        kept = np.ones(n, bool)
        chord_ty = ty.copy()
        for k, j in chords:
            kept[[m % n for m in range(k + 1, j)]] = False
            chord_ty[k % n] = VectorType.FRONTIER
        crossing = _crossing_chords(xy, kept, chords)
        if not crossing:
            break
        chords = [c for c in chords if c not in crossing]
    if kept.sum() < 3 or kept.all():
        return ring
    return Ring(xy[kept], chord_ty[kept])


def _swallowing_chords(xy: np.ndarray, chords, zone: _Zone) -> set:
    """The chords whose stretch (the chain they replace, closed by the chord) holds a
    mapped obstacle or frontier vector deeper than the zone's band plus 1 cm: unexplored
    space the chord would merge as explored (they are undone)."""
    if not chords:
        return set()
    n = len(xy)
    stretch = [shapely.Polygon(xy[[m % n for m in range(k, j + 1)]]) for k, j in chords]
    # a chain and its chord may cross: the stretch is then several pieces
    inner = shapely.buffer(shapely.make_valid(stretch), -(zone.band + MIN_SAMPLE_M))
    hit = np.zeros(len(chords), bool)
    for lines in (zone.obstacles, zone.frontiers):
        if lines is not None:
            hit |= shapely.intersects(lines, inner)
    return {c for c, h in zip(chords, hit, strict=True) if h}


def _crossing_chords(xy: np.ndarray, kept: np.ndarray, chords) -> set:
    """The chords that cross another vector of the trimmed ring (they are undone)."""
    if not chords:
        return set()
    idx = np.flatnonzero(kept)
    a, b = xy[idx], np.roll(xy[idx], -1, axis=0)
    segs = shapely.linestrings(np.stack([a, b], axis=1))
    m = len(idx)
    pos = {int(v): q for q, v in enumerate(idx)}
    chord_at = {pos[k % len(xy)]: (k, j) for k, j in chords}
    tree = shapely.STRtree(segs)
    mine = np.array(sorted(chord_at))
    left, right = tree.query(segs[mine], predicate="intersects")
    out = set()
    for q, r in zip(mine[left], right, strict=True):
        if r != q and (r - q) % m not in (1, m - 1):
            out.add(chord_at[int(q)])
            if int(r) in chord_at:
                out.add(chord_at[int(r)])
    return out


def _edges_allowed(xy: np.ndarray, is_obst: np.ndarray, zone: _Zone, idx) -> np.ndarray:
    """Do vectors ``idx`` (vector i runs from ``xy[i]`` to ``xy[i+1]``) lie in the zone
    for their type?"""
    b = np.roll(xy, -1, axis=0)
    length = np.hypot(*(b[idx] - xy[idx]).T)
    long = length > MAX_EDGE_M  # kept as they are: not worth sampling (see MAX_EDGE_M)
    idx, length = idx[~long], length[~long]
    if not len(idx):
        return np.zeros(len(long), bool)
    counts = np.maximum(2, np.ceil(length / zone.step).astype(int) + 1)
    which = np.repeat(idx, counts)
    t = np.concatenate([np.linspace(0.0, 1.0, c) for c in counts])[:, None]
    pts = xy[which] + t * (b[which] - xy[which])
    obst = is_obst[which]
    ok = zone.allows(pts, obstacle=False)
    ok[obst & ok] = zone.allows(pts[obst & ok], obstacle=True)
    out = np.zeros(len(long), bool)
    out[~long] = np.logical_and.reduceat(ok, np.concatenate([[0], np.cumsum(counts)[:-1]]))
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Maximal cyclic runs of True as (first, last) indices, ``last`` may exceed n."""
    n = len(mask)
    if mask.all():  # nothing new at all: keep a triangle, one vertex per third
        return [(n * k // 3, n * (k + 1) // 3) for k in range(3)]
    start = int(np.flatnonzero(~mask)[0]) + 1  # the first vertex after a kept one
    runs, k = [], start
    while k < start + n:
        if mask[k % n]:
            r0 = k
            while k + 1 < start + n and mask[(k + 1) % n]:
                k += 1
            if k > r0 + 1:
                runs.append((r0, k))
        k += 1
    return runs


def _farthest_chord(xy, n: int, k: int, last: int, zone: _Zone) -> int:
    """The largest ``j`` in ``(k, last]`` such that the chord from vertex ``k`` to
    vertex ``j`` (indices mod n) lies in the zone: found by halving."""
    a = xy[k % n]

    def ok(j: int) -> bool:
        return j == k + 1 or zone.allows_segment(a, xy[j % n], obstacle=False)

    lo, hi = k + 1, last
    if ok(hi):
        return hi
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return lo
