"""Frontier targets: where a robot should go to look at unexplored space.

``frontier_targets``: the merged map's frontier vectors chained into segments, each
with a goal point in explored free space from which the robot sees the frontier
(segments facing a mere sliver of unexplored space are left out) and a utility in
metres: its length (capped) plus ``GAIN_WEIGHT`` times the unexplored area a robot
would see behind it (``unexplored_behind``). Everything that depends on the robots'
lidar (how far a goal may stand off, how far behind a frontier there is area to gain)
comes from a ``Sensor``: a TurtleBot's 3.5 m lidar cannot see past a frontier from a
stand-off chosen for a 30 m one.

    targets = frontier_targets(merged, graph, Sensor.of(cfg.sim.lidar), min_length_m=0.4)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from polyswarm.explore.frontiers import FrontierSegment, extract_frontiers, points_along
from polyswarm.nav.navgraph import NavGraph, clear_of, nodes_of
from polyswarm.polymap import GridPolyMap, VectorType
from polyswarm.raycast import cast_rays


@dataclass(frozen=True)
class Sensor:
    """What exploration needs to know of the robots' lidar."""

    range_m: float = 30.0
    fov_rad: float = 1.5 * math.pi

    @classmethod
    def of(cls, lidar) -> Sensor:
        """From a ``polyswarm.config.LidarConfig``."""
        return cls(lidar.range_max_m, lidar.fov_rad)

    @property
    def sure_range_m(self) -> float:
        """How far the lidar surely sees free space (``polyswarm.slam.scan.NO_RETURN_SHARE``)."""
        return SURE_RANGE_SHARE * self.range_m

    @property
    def goal_offsets_m(self) -> tuple[float, ...]:
        """Stand-offs of goal candidates from the frontier, in order of preference: those
        of ``GOAL_OFFSETS_M`` within ``STANDOFF_SHARE`` of the range."""
        cap = STANDOFF_SHARE * self.range_m
        return tuple(o for o in GOAL_OFFSETS_M if o <= cap) or (cap,)

    @property
    def fallback_radius_m(self) -> float:
        return min(FALLBACK_RADIUS_M, self.sure_range_m)

    @property
    def gain_radius_m(self) -> float:
        return min(GAIN_RADIUS_M, self.sure_range_m)


SURE_RANGE_SHARE = 0.8  # as polyswarm.slam.scan.NO_RETURN_SHARE: no-return beams end there
STANDOFF_SHARE = 0.45  # a goal at most this share of the range from its frontier
GOAL_OFFSETS_M = (0.6, 1.0, 1.5, 0.35)  # goal candidates this far inside the free side
GOAL_ALONG = (0.5, 0.25, 0.75)  # ... at these fractions along the frontier
FALLBACK_RADIUS_M = 4.0  # ... else the nearest graph node this close that sees the frontier
FALLBACK_MIN_SIN = 0.5  # ... preferring views at least 30 degrees off the frontier's line
FALLBACK_GRAZING_PENALTY_M = 10.0  # ... (a grazing view counts as this much farther)
UTILITY_CAP_M = 6.0  # a frontier longer than this is worth no more
# A frontier with explored space this close behind it (on its unexplored side) along
# most (SLIVER_SHARE) of its length borders a sliver, not unexplored space: the thin
# leftovers of keyframe fans, which walls keep from being filled (MergeOptions
# min_growth_m). Looking at them closes nothing; on the thesis' loop, 3 robots were sent
# again and again to such 0.5 m pieces in the middle of corridors.
SLIVER_PROBE_M = 0.15
SLIVER_SHARE = 0.8
PROBE_SPACING_M = 0.25  # probe points along a frontier at most this far apart
# Expected new area: the unexplored space a robot at the frontier would see, estimated
# on rays fanned out from the frontier's middle into its unexplored side, each ending at
# the first obstacle vector on the map. A door into an unexplored room opens onto
# nearly a half disc; a gap left between two keyframes' fans, onto little. With the
# length alone, robots near the end of an exploration went from one small leftover gap
# to the next while a room stayed unexplored (3 robots on the maze, one process, seeds
# 0-4: t99 660 s median with the length alone, 542 s with the area at weight 1 within
# 3 m). Within 3 m a door onto a large unexplored room was worth no more than a wide
# gap (a half disc of 14 m2), and such a room waited while robots travelled to gaps
# (a 126 s coverage plateau in a maze launch); within 6 m (57 m2) the same seeds gave
# 459 s median (4.5 m on seed 4: 533 s, against 494 s at 6 m and 541 s at 3 m).
GAIN_RADIUS_M = 6.0  # how far behind the frontier unexplored space is counted (at most
#                       the sensor's sure range: Sensor.gain_radius_m)
GAIN_RAYS = 9  # rays over the half disc
GAIN_STEPS = 6  # samples per ray (1 m apart)
GAIN_WEIGHT = 1.0  # metres of path a square metre of that area is worth (0: length only)
# a frontier's length counts in full where at least this much unexplored area lies behind
# it, less in proportion below: the two sides of a furniture leg's shadow are long
# frontiers around a sliver of unknown space that the next view from elsewhere fills
LENGTH_GAIN_FULL_M2 = 2.0


@dataclass(frozen=True, eq=False)
class Target:
    goal: np.ndarray  # (2,) a point of explored free space with clearance
    frontier: FrontierSegment
    utility_m: float  # frontier length (capped) + GAIN_WEIGHT x unexplored area behind it

    @property
    def midpoint(self) -> np.ndarray:
        return self.frontier.midpoint


def frontier_targets(
    pmap: GridPolyMap,
    graph: NavGraph,
    min_length_m: float = 0.4,
    max_length_m: float = 4.0,
    separation_m: float = 0.0,
    blacklist: list[np.ndarray] | tuple = (),
    blacklist_radius_m: float = 1.0,
    reach=None,
    cache: TargetCache | None = None,
    sensor: Sensor | None = None,
    facts: tuple | None = None,
) -> list[Target]:
    """Frontier segments with a reachable goal point, longest first.

    A goal is the first candidate (the sensor's ``goal_offsets_m`` into the free side,
    at ``GOAL_ALONG`` of the frontier) that lies in a navigation-graph node (one the
    robots can reach, given ``reach``, a ``polyswarm.explore.assign.Reach``) and at least the
    graph's radius from every obstacle vector; else the nearest such node within the
    sensor's ``fallback_radius_m`` that sees the frontier (a frontier seen through a door
    is looked at from the door).
    Frontiers with no goal, or near a blacklisted point, are not targets.
    ``separation_m`` > 0 keeps one target per neighbourhood (the longest frontier).
    ``cache`` (kept by the caller between calls) saves recomputing segments whose
    surroundings did not change; the result is the same with or without it. ``facts``:
    ``map_facts`` of this map and graph, computed elsewhere (``agents.merger``)."""
    sensor = sensor or Sensor()
    usable = graph.has_node if reach is None else reach.reaches
    if facts is None:
        facts = map_facts(pmap, graph, min_length_m, max_length_m, cache, sensor)
    segs, facts, gains = facts
    if not segs:
        return []
    out = []
    black = np.array(blacklist, dtype=float).reshape(-1, 2)
    node_pts = None
    for seg, f, gain in zip(segs, facts, gains, strict=True):
        if f.sliver:
            continue
        goal = next((p for p, node in f.goals if usable(node)), None)
        if goal is None:  # no room in front of it (a thin wedge seen through a door)
            if node_pts is None:
                node_pts = _node_points(graph, usable)
            goal = _nearest_view_point(
                pmap, node_pts, seg.midpoint, seg.end - seg.start, sensor.fallback_radius_m
            )
        if goal is None:
            continue
        if len(black) and (
            np.hypot(*(black - goal).T).min() < blacklist_radius_m
            or np.hypot(*(black - seg.midpoint).T).min() < blacklist_radius_m
        ):
            continue
        # a frontier's length counts in full only where there is space behind it to see
        length = min(seg.length_m, UTILITY_CAP_M) * min(1.0, gain / LENGTH_GAIN_FULL_M2)
        utility = length + GAIN_WEIGHT * gain
        out.append(Target(goal, seg, utility))
    out.sort(key=lambda t: -t.frontier.length_m)
    if separation_m > 0:
        kept: list[Target] = []
        for t in out:
            if all(np.hypot(*(t.goal - o.goal)) >= separation_m for o in kept):
                kept.append(t)
        out = kept
    return out


def map_facts(pmap, graph, min_length_m, max_length_m, cache=None, sensor=None) -> tuple:
    """The frontier segments of ``pmap``, their facts and the unexplored area behind
    each: what depends on the map and its graph alone (``frontier_targets``)."""
    sensor = sensor or Sensor()
    params = (min_length_m, max_length_m, sensor)
    last = cache.last if cache is not None else None
    if last is not None and last[0] is pmap and last[1] is graph and last[2] == params:
        return last[3]  # nothing changed since the last call (a cycle on an event)
    segs = extract_frontiers(
        pmap, min_length_m, max_length_m, cache.pieces if cache is not None else None
    )
    if not segs:
        return [], [], np.zeros(0)
    # what depends on the map alone is reused while the cells around a segment stay
    offsets = sensor.goal_offsets_m
    reach_m = max(offsets) + graph.radius + SLIVER_PROBE_M
    keys = [(s.points.tobytes(), _cells_around(pmap, s, reach_m)) for s in segs]
    old = cache.entries if cache is not None else {}
    facts = [old.get(key) for key in keys]
    todo = [k for k, f in enumerate(facts) if f is None]
    fresh = _segment_facts(pmap, [segs[k] for k in todo], graph.radius, offsets)
    for k, f in zip(todo, fresh, strict=True):
        facts[k] = f
    if cache is not None:
        cache.entries = dict(zip(keys, facts, strict=True))
    # the unexplored area behind each frontier looks farther: cached on its own
    gains = np.zeros(len(segs))
    if GAIN_WEIGHT > 0:
        radius = sensor.gain_radius_m
        gkeys = [
            None
            if f.sliver
            else (s.points.tobytes(), radius, _cells_versions(pmap, s.midpoint, radius))
            for s, f in zip(segs, facts, strict=True)
        ]
        old_g = cache.gains if cache is not None else {}
        todo = [k for k, key in enumerate(gkeys) if key is not None and key not in old_g]
        behind = unexplored_behind(pmap, [segs[k] for k in todo], radius)
        fresh = dict(zip(todo, behind, strict=True))
        for k, key in enumerate(gkeys):
            if key is not None:
                gains[k] = fresh[k] if k in fresh else old_g[key]
        if cache is not None:
            cache.gains = {key: g for key, g in zip(gkeys, gains, strict=True) if key is not None}
    out = (segs, facts, gains)
    if cache is not None:
        cache.last = (pmap, graph, params, out)
    return out


@dataclass
class TargetCache:
    """Facts of frontier segments that depend on the map alone (sliver or not, goal
    candidates with their graph nodes), kept from one call of ``frontier_targets`` to
    the next for the segments whose surrounding cells did not change."""

    entries: dict = field(default_factory=dict)
    gains: dict = field(default_factory=dict)  # unexplored area behind a segment, m2
    pieces: dict = field(default_factory=dict)  # frontier chains split (``extract_frontiers``)
    last: tuple | None = None  # (map, graph, parameters, result) of the last call


@dataclass(frozen=True)
class _SegmentFacts:
    sliver: bool
    goals: tuple  # ((point, node), ...): goal candidates clear of obstacles, best first


def _cells_around(pmap: GridPolyMap, seg: FrontierSegment, margin_m: float) -> tuple:
    """``box_state`` of the cells a segment's facts depend on: within ``margin_m`` of
    it, and one cell more (the obstacle vectors of neighbouring cells count for
    clearance)."""
    s = pmap.cell_size
    lo = np.floor((seg.points.min(axis=0) - margin_m) / s).astype(int) - 1
    hi = np.floor((seg.points.max(axis=0) + margin_m) / s).astype(int) + 1
    return pmap.box_state(int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1]))


def _cells_versions(pmap: GridPolyMap, xy: np.ndarray, r: float) -> tuple:
    """``box_state`` of the cells within ``r`` metres of a point (a box)."""
    s = pmap.cell_size
    i0, j0 = math.floor((xy[0] - r) / s), math.floor((xy[1] - r) / s)
    i1, j1 = math.floor((xy[0] + r) / s), math.floor((xy[1] + r) / s)
    return pmap.box_state(i0, j0, i1, j1)


def _segment_facts(
    pmap: GridPolyMap,
    segs: list[FrontierSegment],
    radius: float,
    offsets_m: tuple[float, ...] = GOAL_OFFSETS_M,
) -> list[_SegmentFacts]:
    """Sliver test and goal candidates (``offsets_m`` into the free side at
    ``GOAL_ALONG`` of the segment, in explored space, ``radius`` from every obstacle,
    in a convex piece of the map), for many segments in one pass."""
    if not segs:
        return []
    slivers = sliver_frontiers(pmap, segs)
    cands, owner = [], []
    along, offsets = np.array(GOAL_ALONG), np.array(offsets_m)
    for k, seg in enumerate(segs):
        d = seg.end - seg.start
        n = np.hypot(*d)
        if n < 1e-9 or slivers[k]:
            continue
        left = np.array([-d[1], d[0]]) / n  # explored space is on the left
        at = points_along(seg.points, along * seg.length_m)
        # in order of preference: each point along, each offset from it
        cands.append((at[:, None, :] + offsets[None, :, None] * left).reshape(-1, 2))
        owner.append(np.full(len(along) * len(offsets), k))
    goals: list[list] = [[] for _ in segs]
    if cands:
        cands = np.concatenate(cands)
        owner = np.concatenate(owner)
        free = pmap.is_free_many(cands)
        cells = {pmap.cell_index(*c) for c in cands[free]}
        ok = np.zeros(len(cands), dtype=bool)
        if free.any():
            # clearance to obstacles only: the goal may be close to its frontier
            st, en, _ = pmap.vectors([VectorType.OBSTACLE], _near_cells(pmap, cells))
            ok[free] = clear_of(cands[free], st, en, radius)
        idx = np.nonzero(ok)[0]
        for i, node in zip(idx.tolist(), nodes_of(pmap, cands[idx]), strict=True):
            if node is not None:
                goals[owner[i]].append((cands[i], node))
    return [_SegmentFacts(bool(sl), tuple(g)) for sl, g in zip(slivers, goals, strict=True)]


def unexplored_behind(
    pmap: GridPolyMap, segs: list[FrontierSegment], radius_m: float = GAIN_RADIUS_M
) -> np.ndarray:
    """Per segment: the unexplored area (m2) within ``radius_m`` of its middle, on its
    unexplored side, that is not hidden behind an obstacle vector of the map."""
    out = np.zeros(len(segs))
    if not segs:
        return out
    mids = np.array([s.midpoint for s in segs])
    chord = np.array([s.end - s.start for s in segs])
    ok = np.hypot(chord[:, 0], chord[:, 1]) > 1e-9
    # ray angles: the unexplored side's normal (chord turned right), turned by angles
    # within the half disc
    spread = np.linspace(-0.45 * math.pi, 0.45 * math.pi, GAIN_RAYS)
    angles = (np.arctan2(chord[:, 1], chord[:, 0]) - 0.5 * math.pi)[:, None] + spread
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=2)  # (segments, rays, 2)
    r = (np.arange(GAIN_STEPS) + 0.5) / GAIN_STEPS * radius_m
    samples = mids[:, None, None, :] + r[None, None, :, None] * dirs[:, :, None, :]
    unknown = ~pmap.is_free_many(samples.reshape(-1, 2)).reshape(len(segs), GAIN_RAYS, GAIN_STEPS)
    st, en, _ = pmap.vectors(
        [VectorType.OBSTACLE],
        {c for m in mids for c in pmap.cells_within(m[0], m[1], radius_m)},
    )
    # the first obstacle along each ray
    hit = np.full((len(segs), GAIN_RAYS), np.inf)
    if len(st):
        for k in np.nonzero(ok)[0]:
            hit[k] = cast_rays(mids[k], angles[k], st, en, radius_m)
    seen = unknown & (r[None, None, :] < hit[:, :, None])
    w = r / r.sum()  # samples farther out stand for more area
    half_disc = 0.5 * math.pi * radius_m**2
    out[ok] = ((seen * w).sum(axis=2).mean(axis=1) * half_disc)[ok]
    return out


def sliver_frontiers(pmap: GridPolyMap, segs: list[FrontierSegment]) -> np.ndarray:
    """Per segment: does explored space lie ``SLIVER_PROBE_M`` behind it along at least
    ``SLIVER_SHARE`` of its length?"""
    if not segs:
        return np.zeros(0, dtype=bool)
    # every segment's vectors at once (the pairs across two segments left out)
    sizes = np.array([len(s.points) for s in segs])
    pts = np.concatenate([s.points for s in segs])
    seg_of = np.repeat(np.arange(len(segs)), sizes - 1)
    last = np.cumsum(sizes) - 1
    keep = np.ones(len(pts) - 1, dtype=bool)
    keep[last[:-1]] = False
    a = pts[:-1][keep]
    d = (pts[1:] - pts[:-1])[keep]
    L = np.hypot(d[:, 0], d[:, 1])
    ok = L > 1e-9
    a, d, L, seg_of = a[ok], d[ok], L[ok], seg_of[ok]
    right = np.stack([d[:, 1], -d[:, 0]], axis=1) / L[:, None]  # the unexplored side
    m = np.maximum(1, np.ceil(L / PROBE_SPACING_M)).astype(int)
    v = np.repeat(np.arange(len(L)), m)
    t = (np.arange(len(v)) - np.repeat(np.cumsum(m) - m, m) + 0.5) / m[v]
    probes = a[v] + t[:, None] * d[v] + SLIVER_PROBE_M * right[v]
    w = L[v] / m[v]
    own = seg_of[v]
    free = pmap.is_free_many(probes) if len(probes) else np.zeros(0, dtype=bool)
    total = np.bincount(own, weights=w, minlength=len(segs))
    behind = np.bincount(own, weights=w * free, minlength=len(segs))
    return behind >= SLIVER_SHARE * np.maximum(total, 1e-12)


def _node_points(graph: NavGraph, usable) -> np.ndarray:
    pts = [p for cg in graph.cells.values() for n, p in cg.nodes.items() if usable(n)]
    return np.array(pts, dtype=float).reshape(-1, 2)


def _nearest_view_point(
    pmap: GridPolyMap,
    nodes: np.ndarray,
    target: np.ndarray,
    along: np.ndarray | None = None,
    radius_m: float = FALLBACK_RADIUS_M,
):
    """A graph node point within ``radius_m`` of ``target`` that sees it (the
    straight line between them crosses no obstacle vector): the nearest of those that
    look at the frontier (direction ``along``) from the side rather than along it, as a
    look along a frontier shows nothing behind it."""
    if len(nodes) == 0:
        return None
    d = np.hypot(*(nodes - target).T)
    score = d.copy()
    if along is not None and np.hypot(*along) > 1e-9:
        u = along / np.hypot(*along)
        rel = nodes - target  # 2D cross product (numpy's np.cross of 2-vectors is deprecated)
        sin = np.abs(u[0] * rel[:, 1] - u[1] * rel[:, 0]) / np.maximum(d, 1e-9)
        score = d + FALLBACK_GRAZING_PENALTY_M * (sin < FALLBACK_MIN_SIN)
    order = np.argsort(score)
    order = order[d[order] <= radius_m]
    if len(order) == 0:
        return None
    s, e, _ = pmap.vectors([VectorType.OBSTACLE], pmap.cells_within(target[0], target[1], radius_m))
    for k in order[:32]:
        if not _crosses_any(nodes[k], target, s, e):
            return nodes[k].copy()
    return None


def _crosses_any(a: np.ndarray, b: np.ndarray, s: np.ndarray, e: np.ndarray) -> bool:
    """Does segment a-b properly cross any segment s[k]-e[k]?"""
    if len(s) == 0:
        return False

    def orient(p, q, r):
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (
            r[..., 0] - p[..., 0]
        )

    d1, d2 = orient(s, e, a), orient(s, e, b)
    d3, d4 = orient(a, b, s), orient(a, b, e)
    return bool(np.any((d1 * d2 < 0) & (d3 * d4 < 0)))


def _near_cells(pmap: GridPolyMap, cells) -> list:
    return sorted(
        {(i + di, j + dj) for i, j in cells for di in (-1, 0, 1) for dj in (-1, 0, 1)}
        & set(pmap.cells)
    )
