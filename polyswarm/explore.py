"""Frontier-based exploration: targets, path costs and assignment strategies.

* ``frontier_targets``: the merged map's frontier vectors chained into segments, each
  with a goal point in explored free space from which the robot sees the frontier
  (segments facing a mere sliver of unexplored space are left out) and a utility in
  metres: its length (capped) plus ``GAIN_WEIGHT`` times the unexplored area a robot
  would see behind it (``unexplored_behind``);
* ``path_costs``: shortest-path lengths over the navigation graph from every robot to
  every goal (one Dijkstra per robot, scipy);
* ``assign``: which robot goes where, by strategy:
  - ``hungarian``: optimal one-to-one assignment of robots to targets minimising
    ``cost - utility`` (scipy ``linear_sum_assignment``), one robot per frontier chain
    before a second to any (given the targets' chains);
  - ``greedy``: Burgard-style sequential cost-utility with utility discounted around
    targets already taken;
  - ``nearest``: the explore_lite-style baseline, every robot its own nearest target
    (path length; utility breaks ties only), no coordination.
  All keep a robot's current target unless another is clearly better (hysteresis).

    targets = frontier_targets(merged, graph, min_length_m=0.4, max_length_m=4.0)
    costs = path_costs(graph, merged, robot_xy, [t.goal for t in targets])
    choice = assign(Strategy.HUNGARIAN, costs, [t.utility_m for t in targets], current)
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from polyswarm.config import Strategy
from polyswarm.frontiers import FrontierSegment, extract_frontiers, points_along
from polyswarm.navgraph import TIGHT_PENALTY_M, NavGraph, clear_of, node_of, nodes_of
from polyswarm.polymap import GridPolyMap, VectorType
from polyswarm.raycast import cast_rays

GOAL_OFFSETS_M = (0.6, 1.0, 1.5, 0.35)  # goal candidates this far inside the free side
GOAL_ALONG = (0.5, 0.25, 0.75)  # ... at these fractions along the frontier
FALLBACK_RADIUS_M = 4.0  # ... else the nearest graph node this close that sees the frontier
FALLBACK_MIN_SIN = 0.5  # ... preferring views at least 30 degrees off the frontier's line
FALLBACK_GRAZING_PENALTY_M = 10.0  # ... (a grazing view counts as this much farther)
UTILITY_CAP_M = 6.0  # a frontier longer than this is worth no more
UTILITY_WEIGHT = 1.0  # metres of path a metre of frontier is worth
UNREACHABLE = math.inf
# ``nearest`` ranks by path length alone, as the baseline and its reference's
# nearest-frontier planner do; utility only breaks ties (a metre of utility counts as a
# millimetre of path). With the full cost - utility (the area behind a frontier
# included), uncoordinated robots already spread out, which is the coordination the
# baseline is there to lack.
NEAREST_TIE_WEIGHT = 1e-3
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
GAIN_RADIUS_M = 6.0  # how far behind the frontier unexplored space is counted
GAIN_RAYS = 9  # rays over the half disc
GAIN_STEPS = 6  # samples per ray (1 m apart)
GAIN_WEIGHT = 1.0  # metres of path a square metre of that area is worth (0: length only)


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
    reach: Reach | None = None,
    cache: TargetCache | None = None,
) -> list[Target]:
    """Frontier segments with a reachable goal point, longest first.

    A goal is the first candidate (offsets ``GOAL_OFFSETS_M`` into the free side, at
    ``GOAL_ALONG`` of the frontier) that lies in a navigation-graph node (one the
    robots can reach, given ``reach``) and at least the graph's radius from every
    obstacle vector; else the nearest such node within ``FALLBACK_RADIUS_M`` that sees
    the frontier (a frontier seen through a door is looked at from the door).
    Frontiers with no goal, or near a blacklisted point, are not targets.
    ``separation_m`` > 0 keeps one target per neighbourhood (the longest frontier).
    ``cache`` (kept by the caller between calls) saves recomputing segments whose
    surroundings did not change; the result is the same with or without it."""
    usable = graph.has_node if reach is None else reach.reaches
    segs = extract_frontiers(pmap, min_length_m, max_length_m)
    if not segs:
        return []
    # what depends on the map alone is reused while the cells around a segment stay
    reach_m = max(GOAL_OFFSETS_M) + graph.radius + SLIVER_PROBE_M
    keys = [(s.points.tobytes(), _cells_around(pmap, s, reach_m)) for s in segs]
    old = cache.entries if cache is not None else {}
    facts = [old.get(key) for key in keys]
    todo = [k for k, f in enumerate(facts) if f is None]
    for k, f in zip(todo, _segment_facts(pmap, [segs[k] for k in todo], graph.radius), strict=True):
        facts[k] = f
    if cache is not None:
        cache.entries = dict(zip(keys, facts, strict=True))
    # the unexplored area behind each frontier looks farther: cached on its own
    gains = np.zeros(len(segs))
    if GAIN_WEIGHT > 0:
        gkeys = [
            None if f.sliver else (s.points.tobytes(), _cells_versions(pmap, s.midpoint))
            for s, f in zip(segs, facts, strict=True)
        ]
        old_g = cache.gains if cache is not None else {}
        todo = [k for k, key in enumerate(gkeys) if key is not None and key not in old_g]
        fresh = dict(zip(todo, unexplored_behind(pmap, [segs[k] for k in todo]), strict=True))
        for k, key in enumerate(gkeys):
            if key is not None:
                gains[k] = fresh[k] if k in fresh else old_g[key]
        if cache is not None:
            cache.gains = {key: g for key, g in zip(gkeys, gains, strict=True) if key is not None}
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
            goal = _nearest_view_point(pmap, node_pts, seg.midpoint, seg.end - seg.start)
        if goal is None:
            continue
        if len(black) and (
            np.hypot(*(black - goal).T).min() < blacklist_radius_m
            or np.hypot(*(black - seg.midpoint).T).min() < blacklist_radius_m
        ):
            continue
        utility = min(seg.length_m, UTILITY_CAP_M) + GAIN_WEIGHT * gain
        out.append(Target(goal, seg, utility))
    out.sort(key=lambda t: -t.frontier.length_m)
    if separation_m > 0:
        kept: list[Target] = []
        for t in out:
            if all(np.hypot(*(t.goal - o.goal)) >= separation_m for o in kept):
                kept.append(t)
        out = kept
    return out


@dataclass
class TargetCache:
    """Facts of frontier segments that depend on the map alone (sliver or not, goal
    candidates with their graph nodes), kept from one call of ``frontier_targets`` to
    the next for the segments whose surrounding cells did not change."""

    entries: dict = field(default_factory=dict)
    gains: dict = field(default_factory=dict)  # unexplored area behind a segment, m2


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


def _cells_versions(pmap: GridPolyMap, xy: np.ndarray) -> tuple:
    """``box_state`` of the cells within ``GAIN_RADIUS_M`` of a point (a box)."""
    s, r = pmap.cell_size, GAIN_RADIUS_M
    i0, j0 = math.floor((xy[0] - r) / s), math.floor((xy[1] - r) / s)
    i1, j1 = math.floor((xy[0] + r) / s), math.floor((xy[1] + r) / s)
    return pmap.box_state(i0, j0, i1, j1)


def _segment_facts(
    pmap: GridPolyMap, segs: list[FrontierSegment], radius: float
) -> list[_SegmentFacts]:
    """Sliver test and goal candidates (offsets ``GOAL_OFFSETS_M`` into the free side at
    ``GOAL_ALONG`` of the segment, in explored space, ``radius`` from every obstacle,
    in a convex piece of the map), for many segments in one pass."""
    if not segs:
        return []
    slivers = sliver_frontiers(pmap, segs)
    cands, owner = [], []
    along, offsets = np.array(GOAL_ALONG), np.array(GOAL_OFFSETS_M)
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


def unexplored_behind(pmap: GridPolyMap, segs: list[FrontierSegment]) -> np.ndarray:
    """Per segment: the unexplored area (m2) within ``GAIN_RADIUS_M`` of its middle, on
    its unexplored side, that is not hidden behind an obstacle vector of the map."""
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
    r = (np.arange(GAIN_STEPS) + 0.5) / GAIN_STEPS * GAIN_RADIUS_M
    samples = mids[:, None, None, :] + r[None, None, :, None] * dirs[:, :, None, :]
    unknown = ~pmap.is_free_many(samples.reshape(-1, 2)).reshape(len(segs), GAIN_RAYS, GAIN_STEPS)
    st, en, _ = pmap.vectors(
        [VectorType.OBSTACLE],
        {c for m in mids for c in pmap.cells_within(m[0], m[1], GAIN_RADIUS_M)},
    )
    # the first obstacle along each ray
    hit = np.full((len(segs), GAIN_RAYS), np.inf)
    if len(st):
        for k in np.nonzero(ok)[0]:
            hit[k] = cast_rays(mids[k], angles[k], st, en, GAIN_RADIUS_M)
    seen = unknown & (r[None, None, :] < hit[:, :, None])
    w = r / r.sum()  # samples farther out stand for more area
    half_disc = 0.5 * math.pi * GAIN_RADIUS_M**2
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
    pmap: GridPolyMap, nodes: np.ndarray, target: np.ndarray, along: np.ndarray | None = None
):
    """A graph node point within ``FALLBACK_RADIUS_M`` of ``target`` that sees it (the
    straight line between them crosses no obstacle vector): the nearest of those that
    look at the frontier (direction ``along``) from the side rather than along it, as a
    look along a frontier shows nothing behind it."""
    if len(nodes) == 0:
        return None
    d = np.hypot(*(nodes - target).T)
    score = d.copy()
    if along is not None and np.hypot(*along) > 1e-9:
        u = along / np.hypot(*along)
        sin = np.abs(np.cross(np.broadcast_to(u, nodes.shape), nodes - target)) / np.maximum(
            d, 1e-9
        )
        score = d + FALLBACK_GRAZING_PENALTY_M * (sin < FALLBACK_MIN_SIN)
    order = np.argsort(score)
    order = order[d[order] <= FALLBACK_RADIUS_M]
    if len(order) == 0:
        return None
    s, e, _ = pmap.vectors(
        [VectorType.OBSTACLE], pmap.cells_within(target[0], target[1], FALLBACK_RADIUS_M)
    )
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


# --- path costs ------------------------------------------------------------------------------


@dataclass(frozen=True)
class GraphIndex:
    """The navigation graph as a sparse matrix (edge weight: metres via the opening)."""

    nodes: list
    index: dict
    matrix: csr_matrix

    @classmethod
    def build(cls, graph: NavGraph) -> GraphIndex:
        nodes = [n for cg in graph.cells.values() for n in cg.nodes]
        index = {n: k for k, n in enumerate(nodes)}
        points = np.array([p for cg in graph.cells.values() for p in cg.nodes.values()])
        # every edge (both ends known) with its portal's end points
        edges = [
            (ia, ib, p.a, p.b, p.tight)
            for group in (
                *(cg.internal for cg in graph.cells.values()),
                *graph.borders.values(),
            )
            for (a, b), p in group.items()
            if (ia := index.get(a)) is not None and (ib := index.get(b)) is not None
        ]
        n = len(nodes)
        if not edges:
            return cls(nodes, index, csr_matrix((n, n)))
        ia, ib, pa, pb, tight = zip(*edges, strict=True)
        ia, ib = np.array(ia), np.array(ib)
        m = 0.5 * (np.array(pa) + np.array(pb))  # metres via the opening's middle
        d = np.hypot(*(points[ia] - m).T) + np.hypot(*(m - points[ib]).T)
        d += TIGHT_PENALTY_M * np.array(tight)  # as the planner counts a tight passage
        d = np.maximum(d, 1e-6)  # csgraph treats zero as "no edge"
        rows = np.stack([ia, ib], axis=1).ravel()
        cols = np.stack([ib, ia], axis=1).ravel()
        w = np.repeat(d, 2)
        return cls(nodes, index, csr_matrix((w, (rows, cols)), shape=(n, n)))


@dataclass
class Reach:
    """Shortest paths over the graph from every robot (one Dijkstra per robot).

    A point joins the graph at the node of the convex piece holding it (or the nearest
    node within a metre, for a robot standing close to a wall)."""

    graph: NavGraph
    pmap: GridPolyMap
    index: GraphIndex
    sources: list  # per robot: (node index, metres to it) or None
    dist: np.ndarray  # (robots with a node, nodes)

    @classmethod
    def from_robots(
        cls, graph: NavGraph, pmap: GridPolyMap, robots_xy: list, index: GraphIndex | None = None
    ) -> Reach:
        index = index or GraphIndex.build(graph)
        src = [_join(graph, pmap, index, p) if index.nodes else None for p in robots_xy]
        rows = [s[0] for s in src if s is not None]
        if rows:
            dist = dijkstra(index.matrix, directed=False, indices=rows)
        else:
            dist = np.full((0, len(index.nodes)), np.inf)
        return cls(graph, pmap, index, src, np.atleast_2d(dist))

    def reaches(self, node) -> bool:
        """Can some robot reach this node?"""
        k = self.index.index.get(node)
        return k is not None and bool(self._reached[k])

    @functools.cached_property
    def _reached(self) -> np.ndarray:
        return np.isfinite(self.dist).any(axis=0)  # (nodes,): some robot reaches it

    def costs(self, goals: list) -> np.ndarray:
        """(robots, goals) path lengths in metres (inf: unreachable)."""
        out = np.full((len(self.sources), len(goals)), UNREACHABLE)
        dst = [_join(self.graph, self.pmap, self.index, g) for g in goals]
        row = 0
        for k, s in enumerate(self.sources):
            if s is None:
                continue
            for j, d in enumerate(dst):
                if d is not None and math.isfinite(self.dist[row, d[0]]):
                    out[k, j] = s[1] + self.dist[row, d[0]] + d[1]
            row += 1
        return out


def path_costs(
    graph: NavGraph,
    pmap: GridPolyMap,
    sources: list[np.ndarray],
    goals: list[np.ndarray],
    index: GraphIndex | None = None,
) -> np.ndarray:
    """(len(sources), len(goals)) path lengths in metres over the graph (inf: none)."""
    return Reach.from_robots(graph, pmap, sources, index).costs(goals)


def _join(graph: NavGraph, pmap: GridPolyMap, index: GraphIndex, p) -> tuple[int, float] | None:
    p = np.asarray(p, dtype=float)
    node = node_of(pmap, *p)
    if node is not None and node in index.index:
        return index.index[node], float(np.hypot(*(graph.point(node) - p)))
    best, best_d = None, 1.0  # metres: farther than this from any node is not on the graph
    for c in pmap.cells_within(p[0], p[1], 1.0):
        cg = graph.cells.get(c)
        if cg is None:
            continue
        for n, q in cg.nodes.items():
            d = float(np.hypot(*(q - p)))
            if d < best_d:
                best, best_d = n, d
    return None if best is None else (index.index[best], best_d)


# --- assignment ------------------------------------------------------------------------------


def assign(
    strategy: Strategy,
    costs: np.ndarray,
    utilities: np.ndarray | list,
    current: list[int | None] | None = None,
    hysteresis: float = 0.8,
    goals: np.ndarray | None = None,
    separation_m: float = 3.0,
    groups: np.ndarray | list | None = None,
) -> list[int | None]:
    """Target index per robot (None: nothing reachable).

    ``costs`` (robots x targets, metres, inf = unreachable), ``utilities`` (metres of
    frontier). ``current[r]`` is robot r's current target index in this list, whose
    path cost counts ``hysteresis`` times (so a robot switches only for a clearly
    better target). ``goals`` (targets x 2) are used by ``greedy`` to discount targets
    near one already taken. ``groups`` (per target) marks pieces of one frontier:
    ``hungarian`` sends one robot per frontier before it sends a second to any."""
    n_r, n_t = costs.shape
    if n_r == 0:
        return []
    if n_t == 0:
        return [None] * n_r
    util = np.asarray(utilities, dtype=float)
    c = costs.copy()
    for r, t in enumerate(current or []):
        if t is not None and 0 <= t < n_t and math.isfinite(c[r, t]):
            c[r, t] *= hysteresis
    reachable = np.isfinite(c)
    if strategy == Strategy.NEAREST:
        score = np.where(reachable, c - NEAREST_TIE_WEIGHT * util[None, :], np.inf)
        return [int(np.argmin(s)) if np.isfinite(s).any() else None for s in score]
    if strategy == Strategy.GREEDY:
        return _greedy(c, util, goals, separation_m)
    if groups is None:
        return _hungarian(c, util)
    return _hungarian_grouped(c, util, np.asarray(groups))


def _hungarian_grouped(c: np.ndarray, util: np.ndarray, groups: np.ndarray) -> list[int | None]:
    """Robots to frontiers first (each robot to its best piece of its frontier), then
    the robots left over to the remaining pieces. Pieces of one frontier border the same
    unexplored space: two robots sent to it travel as a pack (down a corridor, one
    behind the other) while another frontier waits."""
    n_r, n_t = c.shape
    score = c - UTILITY_WEIGHT * util[None, :]
    keys, col = np.unique(groups, return_inverse=True)
    best = np.full((n_r, len(keys)), np.inf)
    pick = np.full((n_r, len(keys)), -1)
    for j in range(n_t):  # per robot and frontier: its best piece
        better = score[:, j] < best[:, col[j]]
        best[better, col[j]] = score[better, j]
        pick[better, col[j]] = j
    first = _hungarian(best, np.zeros(len(keys)))
    out: list[int | None] = [None if g is None else int(pick[r, g]) for r, g in enumerate(first)]
    spare = [r for r in range(n_r) if out[r] is None]
    if spare:
        taken = {t for t in out if t is not None}
        free = [j for j in range(n_t) if j not in taken]
        if free:
            second = _hungarian(c[np.ix_(spare, free)], util[free])
            for r, t in zip(spare, second, strict=True):
                out[r] = None if t is None else free[t]
    return out


def _hungarian(c: np.ndarray, util: np.ndarray) -> list[int | None]:
    n_r = c.shape[0]
    score = c - UTILITY_WEIGHT * util[None, :]
    big = 1e6 + np.nanmax(np.where(np.isfinite(score), np.abs(score), 0.0))
    m = np.where(np.isfinite(score), score, big)
    rows, cols = linear_sum_assignment(m)
    out: list[int | None] = [None] * n_r
    for r, t in zip(rows, cols, strict=True):
        if np.isfinite(score[r, t]):
            out[r] = int(t)
    # more robots than targets: the rest wait (two robots on one target jam doors)
    return out


def _greedy(
    c: np.ndarray, util: np.ndarray, goals: np.ndarray | None, separation_m: float
) -> list[int | None]:
    """Burgard et al. 2005: robots in turn take the best cost-utility target, then the
    utility of targets around it drops (they will be seen from there)."""
    n_r = c.shape[0]
    u = util.astype(float).copy()
    out: list[int | None] = [None] * n_r
    todo = list(range(n_r))
    while todo:
        best = None
        for r in todo:
            s = np.where(np.isfinite(c[r]), c[r] - UTILITY_WEIGHT * u, np.inf)
            t = int(np.argmin(s))
            if np.isfinite(s[t]) and (best is None or s[t] < best[2]):
                best = (r, t, s[t])
        if best is None:
            break
        r, t, _ = best
        out[r] = t
        todo.remove(r)
        if goals is not None and separation_m > 0:
            d = np.hypot(*(goals - goals[t]).T)
            u = u * np.where(d < separation_m, d / separation_m, 1.0)
        else:
            u[t] = 0.0
    return out
