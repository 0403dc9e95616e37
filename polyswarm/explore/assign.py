"""Frontier-based exploration: path costs and assignment strategies.

(The targets themselves, frontier segments with goal points and utilities, are made
by ``polyswarm.explore.targets``.)

* ``path_costs``: shortest-path lengths over the navigation graph from every robot to
  every goal (one Dijkstra per robot, scipy);
* ``assign``: which robot goes where, by strategy:
  - ``hungarian``: optimal one-to-one assignment of robots to targets minimising
    ``cost - utility`` (scipy ``linear_sum_assignment``), one robot per group of
    targets (a frontier chain, or targets close together) before a second to any; a
    robot left over waits, or (a ``follower``) goes to its nearest target;
  - ``greedy``: Burgard-style sequential cost-utility with utility discounted around
    targets already taken;
  - ``nearest``: the explore_lite-style baseline, every robot its own nearest target
    (path length; utility breaks ties only), no coordination.
  All keep a robot's current target unless another is clearly better (hysteresis).

    targets = frontier_targets(merged, graph, Sensor(30.0, 4.71))
    costs = path_costs(graph, merged, robot_xy, [t.goal for t in targets])
    choice = assign(Strategy.HUNGARIAN, costs, [t.utility_m for t in targets], current)
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from polyswarm.config import Strategy
from polyswarm.nav.navgraph import TIGHT_PENALTY_M, NavGraph, node_of
from polyswarm.polymap import GridPolyMap

UNREACHABLE = math.inf
UTILITY_WEIGHT = 1.0  # metres of path a metre of frontier is worth
# ``nearest`` ranks by path length alone, as the baseline and its reference's
# nearest-frontier planner do; utility only breaks ties (a metre of utility counts as a
# millimetre of path). With the full cost - utility (the area behind a frontier
# included), uncoordinated robots already spread out, which is the coordination the
# baseline is there to lack.
NEAREST_TIE_WEIGHT = 1e-3

__all__ = ["GraphIndex", "Reach", "Strategy", "assign", "path_costs"]


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
    followers: list[bool] | None = None,
) -> list[int | None]:
    """Target index per robot (None: nothing reachable, or left over and no follower).

    ``costs`` (robots x targets, metres, inf = unreachable), ``utilities`` (metres of
    frontier). ``current[r]`` is robot r's current target index in this list, whose
    path cost counts ``hysteresis`` times (so a robot switches only for a clearly
    better target). ``goals`` (targets x 2) are used by ``greedy`` to discount targets
    near one already taken. ``groups`` (per target) marks pieces of one frontier:
    ``hungarian`` sends one robot per frontier before it sends a second to any.
    ``followers[r]``: robot r, if ``hungarian`` leaves it over, goes to its nearest
    target (taken by another robot) instead of getting none; every robot when None."""
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
        out = _hungarian(c, util)
    else:
        out = _hungarian_grouped(c, util, np.asarray(groups))
    return _followers_to_nearest(c, out, followers or [True] * n_r)


def target_groups(chains, goals: np.ndarray, separation_m: float) -> np.ndarray:
    """Group number per target: pieces of one frontier chain, and targets whose goals lie
    within ``separation_m`` of the first target of a group (two robots sent through one
    door into one room block each other there). A group's targets lie within two
    separations of each other: chaining neighbours to neighbours made one group of
    every door along a corridor, and robots left whole rooms for a pillar's shadow."""
    g = np.asarray(goals, dtype=float).reshape(-1, 2)
    out = np.full(len(g), -1)
    seeds: list[int] = []  # the first target of each group
    by_chain: dict = {}
    for i, ch in enumerate(chains):
        if ch in by_chain:
            out[i] = out[by_chain[ch]]
            continue
        near = [k for k in seeds if np.hypot(*(g[k] - g[i])) < separation_m]
        if near:
            out[i] = out[near[0]]
        else:
            out[i] = i
            seeds.append(i)
        by_chain[ch] = i
    return out


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
    return out


def _followers_to_nearest(
    c: np.ndarray, out: list[int | None], followers: list[bool]
) -> list[int | None]:
    """More robots than targets: each follower left over goes to its nearest target (its
    current one, by the hysteresis), as the reference planner's ``hungarian`` sends
    every robot left over."""
    return [
        int(np.argmin(row)) if t is None and f and np.isfinite(row).any() else t
        for t, row, f in zip(out, c, followers, strict=True)
    ]


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
