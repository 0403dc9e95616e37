"""Path planning on a PolyMap: A* over the topological graph, then a taut path.

1. A* over the graph's nodes (convex pieces), moving from opening to opening, from
   the piece holding the start to the piece holding the goal.
   A tight passage (``Portal.tight``: room at the graph's tight radius only) costs
   ``TIGHT_PENALTY_M`` more.
2. The pieces found make a sleeve; its configuration space (the sleeve minus every
   obstacle vector grown by the radius and frontier vector grown by the frontier
   radius - grown by circumscribed polygons, so the clearance is never less; the two
   pieces at a tight passage keep the tight radius) is triangulated. Start and goal may
   be closer (the robot is there; a frontier goal lies at the frontier): they join the
   nearest point of that space. If the space is cut, the check is repeated with every
   piece of the cells around the cut (a cell fanned into slivers); if it is still
   cut, the opening into the first piece the start cannot reach is blocked and A*
   tries again.
3. A* over the triangles and the funnel algorithm (string pulling through the shared
   edges) give the shortest path inside the sleeve: taut, and at least the radius from
   every obstacle vector. The thesis' paths went from polygon centre to polygon centre
   and were 29% longer than a grid planner's (its Table 4.2).

    planner = Planner(pmap, graph)
    path = planner.plan(start_xy, goal_xy)      # PlanningError if impossible
    path.points, path.length_m
    path = planner.plan(start_xy, goal_xy, partial=True)  # else as close as the map lets
    path.reaches_goal                           # False: it ends short of the goal
"""

from __future__ import annotations

import heapq
import itertools
import math
from dataclasses import dataclass, field

import mapbox_earcut
import numpy as np
import shapely
import shapely.ops

from polyswarm.errors import OffMapError, PlanningError
from polyswarm.nav.navgraph import (
    BOUNDARY,
    BUFFER_SEGMENTS,
    TIGHT_PENALTY_M,
    NavGraph,
    NodeId,
    Portal,
    grown_radius,
    node_of,
    piece_polygon,
)
from polyswarm.polymap import GridPolyMap, VectorType

ENTRY_INSET_M = 2e-3  # an entry point lies this far inside the free space
JOIN_M = 1.0  # start or goal this close to the robot's free space joins it straight
MAX_SLEEVE_RETRIES = 4  # openings blocked by the exact check before giving up
# a partial path (``plan(partial=True)``) must end at least this much closer to the goal
# than the start is: otherwise the robot would only shuffle on the spot
PARTIAL_GAIN_M = 0.5


@dataclass(frozen=True)
class Path:
    points: np.ndarray  # (k, 2) metres
    nodes: tuple[NodeId, ...]
    expansions: int
    reaches_goal: bool = True  # False: a partial path, to the nearest point it could reach

    @property
    def length_m(self) -> float:
        return (
            float(np.hypot(*np.diff(self.points, axis=0).T).sum()) if len(self.points) > 1 else 0.0
        )


class Planner:
    def __init__(self, pmap: GridPolyMap, graph: NavGraph, seen: np.ndarray | None = None) -> None:
        """``seen``: (k, 2) points of obstacles the robot's lidar saw that the map does not
        hold (a wall the merge lost, a door closed since): kept from as from walls."""
        self.map = pmap
        self.graph = graph
        self.seen = np.zeros((0, 2)) if seen is None else np.asarray(seen, dtype=float)
        self.radius = graph.radius
        self.frontier_radius = graph.frontier_radius

    def plan(self, start, goal, partial: bool = False) -> Path:
        """The shortest path with the graph's clearance from start to goal.

        With ``partial``, a goal the robot cannot reach (the map's free space is cut
        short of it, often by a frontier just past a narrow door) gives the path to the
        nearest point it can reach instead, if that is at least ``PARTIAL_GAIN_M``
        closer to the goal: an exploring robot drives as close as it can and looks,
        and the frontier retreats. Raises PlanningError otherwise."""
        start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
        # a start or goal in a piece too tight for the robot joins the graph nearby; so
        # does a robot standing in a sliver the map left unexplored (it is on free space)
        s_node = node_of(self.map, *start)
        sources = self._entries(s_node, start)
        if s_node is None and not sources:
            raise OffMapError(f"start {_xy(start)} is not in explored free space")
        g_node = node_of(self.map, *goal)
        if g_node is None:
            raise PlanningError(f"goal {_xy(goal)} is in unexplored space (or in an obstacle)")
        targets = self._entries(g_node, goal)
        if not sources or not targets:
            where = "start" if not sources else "goal"
            raise PlanningError(f"no room for radius {self.radius:.3f} m near the {where}")
        blocked: set[tuple[NodeId, NodeId]] = set()
        expansions = 0
        nearest: Path | None = None  # of the sleeves tried, the path nearest the goal
        why = f"no path from {_xy(start)} to {_xy(goal)} for radius {self.radius:.3f} m"
        for _ in range(MAX_SLEEVE_RETRIES + 1):
            nodes, n_exp = self._astar(sources, targets, goal, blocked)
            expansions += n_exp
            if nodes is None:
                break
            sleeve = self._taut(nodes, start, goal, (s_node, g_node))
            if sleeve.cut_cell is not None:  # cut: perhaps only the route's pieces are thin
                sleeve = self._taut(nodes, start, goal, (s_node, g_node), sleeve.cut_cell)
            if sleeve.path is not None:
                return Path(sleeve.path, tuple(nodes), expansions)
            blocked |= sleeve.cut
            if sleeve.towards is not None and (
                nearest is None or _gap(sleeve.towards, goal) < _gap(nearest.points, goal)
            ):
                nearest = Path(sleeve.towards, tuple(nodes), expansions, reaches_goal=False)
            why = f"no path with {self.radius:.3f} m clearance from {_xy(start)} to {_xy(goal)}"
        if (
            partial
            and nearest is not None
            and (_gap(start[None], goal) - _gap(nearest.points, goal) >= PARTIAL_GAIN_M)
        ):
            return nearest
        raise PlanningError(why)

    def _entries(
        self, node: NodeId | None, p: np.ndarray
    ) -> dict[NodeId, tuple[float, np.ndarray]]:
        """Graph nodes a point joins: its own piece's, else those within ``JOIN_M``."""
        if node is not None and self.graph.has_node(node):
            return {node: (0.0, p)}
        out = {}
        for c in self.map.cells_within(p[0], p[1], JOIN_M):
            cg = self.graph.cells.get(c)
            if cg is None:
                continue
            for n, q in cg.nodes.items():
                d = float(np.hypot(*(q - p)))
                if d <= JOIN_M:
                    out[n] = (d, q)
        return out

    # -- 1. A* over the graph -------------------------------------------------------------

    def _astar(self, sources: dict, targets: dict, goal, blocked):
        tie = itertools.count()
        best: dict[NodeId, float] = {}
        pos: dict[NodeId, np.ndarray] = {}
        parent: dict[NodeId, NodeId] = {}
        heap = []
        for n, (d, q) in sources.items():
            best[n], pos[n] = d, q
            heapq.heappush(heap, (d + float(np.hypot(*(goal - q))), next(tie), n))
        closed = set()
        exp = 0
        while heap:
            _, _, n = heapq.heappop(heap)
            if n in closed:
                continue
            if n in targets:
                out = [n]
                while out[-1] in parent:
                    out.append(parent[out[-1]])
                return out[::-1], exp
            closed.add(n)
            exp += 1
            here = pos[n]
            for m, portal in self.graph.neighbours(n):
                if m in closed or (n, m) in blocked or (m, n) in blocked:
                    continue
                # enter m at the point of its opening closest to the straight line on
                cross = _closest_on_segment(portal.a, portal.b, here, goal)
                cost = best[n] + float(np.hypot(*(cross - here))) + TIGHT_PENALTY_M * portal.tight
                if m in targets:
                    cost += float(np.hypot(*(goal - cross)))
                if cost < best.get(m, math.inf):
                    best[m] = cost
                    pos[m] = cross
                    parent[m] = n
                    h = 0.0 if m in targets else float(np.hypot(*(goal - cross)))
                    heapq.heappush(heap, (cost + h, next(tie), m))
        return None, exp

    # -- 2./3. the taut path in the sleeve ------------------------------------------------

    def _taut(
        self, nodes, start, goal, ends=(), widen_at: tuple[int, int] | None = None
    ) -> _Sleeve:
        """The exact check of one A* route. ``widen_at`` (a cell where the route was
        cut): every piece of that cell and its eight neighbours joins the sleeve - a
        convex partition can fan a cell's free space into slivers from one corner, and
        a route along slivers has no room for the radius where the cell has plenty (a
        door reached along a 0.3 m sliver of a 2 m corridor). Nine cells at most: the
        cost does not grow with the route."""
        # the start's and goal's pieces too (a start in an unexplored sliver has none)
        pieces = list(dict.fromkeys([*nodes, *(e for e in ends if e is not None)]))
        if widen_at is not None:
            i, j = widen_at
            for c in itertools.product((i - 1, i, i + 1), (j - 1, j, j + 1)):
                cg = self.graph.cells.get(c)
                pieces += [] if cg is None else list(cg.nodes)
            pieces = list(dict.fromkeys(pieces))
        polys = [shapely.Polygon(piece_polygon(self.map, n)) for n in pieces]
        sleeve = shapely.union_all(polys, grid_size=1e-6)
        x0, y0, x1, y1 = sleeve.bounds
        r = self.radius
        reach = r + 0.05
        cells = [
            (i, j)
            for i in range(
                math.floor((x0 - reach) / self.map.cell_size),
                math.floor((x1 + reach) / self.map.cell_size) + 1,
            )
            for j in range(
                math.floor((y0 - reach) / self.map.cell_size),
                math.floor((y1 + reach) / self.map.cell_size) + 1,
            )
        ]
        st, en, ty = self.map.vectors(BOUNDARY, cells)
        frontier = ty == int(VectorType.FRONTIER)
        if len(st):  # only walls whose grown shape can reach the sleeve: a long diagonal
            # path's box holds most of the map, and growing all of it was one GEOS call of
            # seconds on a loaded machine (an agent killed in it at shutdown)
            shapely.prepare(sleeve)
            lines = shapely.linestrings(np.stack([st, en], axis=1))
            near = shapely.dwithin(sleeve, lines, grown_radius(r) + 1e-3)
            st, en, frontier = st[near], en[near], frontier[near]
        seen = self._seen_near(sleeve, r)
        free = shapely.difference(sleeve, self._grown(st, en, frontier, r, seen), grid_size=1e-6)
        # a tight passage on the route: its two pieces keep only the tight radius
        tight = {
            k
            for i, (a, b) in enumerate(itertools.pairwise(nodes))
            if _portal(self.graph, a, b).tight
            for k in (i, i + 1)
        }
        if tight:
            narrow = shapely.union_all([polys[k] for k in sorted(tight)], grid_size=1e-6)
            grown = self._grown(st, en, frontier, self.graph.tight_radius, seen)
            free = shapely.union(
                free, shapely.difference(narrow, grown, grid_size=1e-6), grid_size=1e-6
            )
        # the goal's part of the free space first: a robot standing too close to a
        # wall (in a doorway) joins that part if it can, not merely the nearest part
        part_g, g_eff = _component_and_entry(free, goal)
        part_s, s_eff = _component_and_entry(free, start, prefer=part_g)
        if part_s is None:
            return _Sleeve(cut=_narrowest_openings(self.graph, nodes))
        if part_g is None or not part_s.equals(part_g):
            # the sleeve is cut by obstacles: block the opening into the first piece of
            # the route the start's part of the free space does not reach
            k = _first_not_entered(polys[: len(nodes)], part_s)
            return _Sleeve(
                cut=_narrowest_openings(self.graph, nodes)
                if k == 0
                else {(nodes[k - 1], nodes[k])},
                towards=self._towards(part_s, s_eff, start, goal),
                cut_cell=None if k == 0 or widen_at is not None else nodes[k][:2],
            )
        inner = shapely.set_precision(part_s, 1e-6)
        tri_pts = _channel(inner, s_eff, g_eff)
        if tri_pts is None:
            return _Sleeve(cut=_narrowest_openings(self.graph, nodes))
        return _Sleeve(path=_with_ends(tri_pts, start, s_eff, goal, g_eff))

    def _seen_near(self, sleeve, r: float) -> np.ndarray:
        if not len(self.seen):
            return self.seen
        near = shapely.dwithin(sleeve, shapely.points(self.seen), grown_radius(r) + 1e-3)
        return self.seen[near]

    def _grown(self, st, en, frontier, radius: float, seen=()):
        """Obstacle vectors (and ``seen`` points) grown by ``radius`` and frontier vectors
        by the frontier radius, each by a circumscribed polygon (never closer than that)."""
        parts = [
            shapely.buffer(
                shapely.multilinestrings(np.stack([st[m], en[m]], axis=1)),
                grown_radius(g),
                quad_segs=BUFFER_SEGMENTS,
            )
            for m, g in ((~frontier, radius), (frontier, self.frontier_radius))
            if m.any() and g > 0
        ]
        if len(seen):  # one disc per point, then one union: the same shape as buffering
            # the MultiPoint, which GEOS nodes all at once (2,000 points: 3.5-5.7 s against
            # 0.04 s, seen-buffer.json; an agent boxed in by robots planned for minutes)
            discs = shapely.buffer(
                shapely.points(seen), grown_radius(radius), quad_segs=BUFFER_SEGMENTS
            )
            parts.append(shapely.union_all(discs))
        return shapely.union_all(parts) if parts else shapely.Polygon()

    def _towards(self, part, s_eff, start, goal) -> np.ndarray | None:
        """The path within ``part`` (the start's free space) to its point nearest the goal."""
        inner = part.buffer(-ENTRY_INSET_M)
        if inner.is_empty:
            return None
        end = np.asarray(shapely.ops.nearest_points(inner, shapely.Point(goal))[0].coords[0])
        tri_pts = _channel(shapely.set_precision(part, 1e-6), s_eff, end)
        return None if tri_pts is None else _with_ends(tri_pts, start, s_eff, end, end)


@dataclass(frozen=True)
class _Sleeve:
    """What the exact check of one A* route found: the path, or the openings to block
    (and the path towards the goal as far as the route's free space reaches)."""

    path: np.ndarray | None = None
    cut: set = field(default_factory=set)
    towards: np.ndarray | None = None
    cut_cell: tuple[int, int] | None = None  # where the route was cut (not yet widened)


def _with_ends(tri_pts, start, s_eff, goal, g_eff) -> np.ndarray:
    """The channel's path with the true start and goal (they may lie a little outside
    the free space: the robot stands there; a frontier goal lies at the frontier)."""
    pts = [start] if np.hypot(*(start - s_eff)) > 1e-9 else []
    pts += list(tri_pts)
    if np.hypot(*(goal - g_eff)) > 1e-9:
        pts.append(goal)
    return _dedupe(np.array(pts))


def _xy(p) -> str:
    """A point for a message: ``(15.74, 8.15)`` (metres)."""
    return f"({p[0]:.2f}, {p[1]:.2f})"


def _gap(points: np.ndarray, goal: np.ndarray) -> float:
    """Metres from a path's end to the goal."""
    return float(np.hypot(*(points[-1] - goal)))


def _first_not_entered(polys, part) -> int:
    """The index of the first piece of the route that ``part`` (the start's free space)
    does not enter; 0 if it enters them all (then the narrowest opening is blamed)."""
    entered = shapely.area(shapely.intersection(polys, part)) > 1e-6
    return int(np.argmin(entered)) if not entered.all() else 0


def _closest_on_segment(a, b, p, goal) -> np.ndarray:
    """The point of opening a-b nearest to the line from p to the goal (clamped)."""
    d = b - a
    L2 = float(np.dot(d, d))
    if L2 == 0:
        return a.copy()
    # intersect the line p->goal with the segment if possible, else nearest endpoint
    v = goal - p
    den = d[0] * v[1] - d[1] * v[0]
    if abs(den) > 1e-12:
        t = ((p[0] - a[0]) * v[1] - (p[1] - a[1]) * v[0]) / den
        if 0.0 <= t <= 1.0:
            return a + t * d
    t = np.clip(np.dot(p - a, d) / L2, 0.0, 1.0)
    return a + t * d


def _portal(graph: NavGraph, a: NodeId, b: NodeId) -> Portal:
    """The opening from node a to its neighbour b."""
    return next(p for m, p in graph.neighbours(a) if m == b)


def _narrowest_openings(graph: NavGraph, nodes) -> set:
    worst, edge = math.inf, None
    for a, b in itertools.pairwise(nodes):
        for m, portal in graph.neighbours(a):
            if m == b and portal.width < worst:
                worst, edge = portal.width, (a, b)
    return {edge} if edge else set()


def _component_and_entry(free, p, prefer=None):
    """The part of the free space holding p (or nearest to it; ``prefer`` if it is
    within ``JOIN_M``) and a point in it."""
    parts = [g for g in shapely.get_parts(free) if not g.is_empty and g.area > 1e-9]
    if not parts:
        return None, None
    pt = shapely.Point(p)
    for g in parts:
        if g.covers(pt):
            return g, np.asarray(p, dtype=float)
    d = [g.distance(pt) for g in parts]
    g = parts[int(np.argmin(d))]
    if prefer is not None and prefer.distance(pt) <= JOIN_M:
        g = prefer
    elif min(d) > JOIN_M:  # farther than this from any room for the robot
        return None, None
    # the nearest point a few millimetres inside, so it is strictly in the free space
    inner = g.buffer(-ENTRY_INSET_M)
    if inner.is_empty:
        return g, np.asarray(g.representative_point().coords[0])
    return g, np.asarray(shapely.ops.nearest_points(inner, pt)[0].coords[0])


def _channel(poly: shapely.Polygon, start: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
    """Shortest path inside ``poly``: triangulate, A* over triangles, funnel."""
    rings = [np.asarray(poly.exterior.coords)[:-1]] + [
        np.asarray(r.coords)[:-1] for r in poly.interiors
    ]
    xy = np.concatenate(rings)
    ends = np.cumsum([len(r) for r in rings]).astype(np.uint32)
    tri = mapbox_earcut.triangulate_float64(xy, ends).astype(np.int64).reshape(-1, 3)
    if len(tri) == 0:
        return None
    q = np.rint(xy * 1e6).astype(np.int64)
    _, first, inv = np.unique(q, axis=0, return_index=True, return_inverse=True)
    tri = first[inv.ravel()][tri]
    # earcut can return triangles outside a polygon whose rings touch themselves (a
    # PolySLAM map's piece did: one triangle spanned the office, and the "shortest path"
    # went straight through four walls); keep only those inside
    cent = (xy[tri[:, 0]] + xy[tri[:, 1]] + xy[tri[:, 2]]) / 3.0
    shapely.prepare(poly)
    tri = tri[shapely.contains_xy(poly, cent[:, 0], cent[:, 1])]
    if len(tri) == 0:
        return None
    a, b, c = xy[tri[:, 0]], xy[tri[:, 1]], xy[tri[:, 2]]
    ts, tg = _locate(a, b, c, start), _locate(a, b, c, goal)
    if ts is None or tg is None:
        return None
    if ts == tg:
        return np.array([start, goal])
    edges: dict[tuple[int, int], list[int]] = {}
    for k, t in enumerate(tri.tolist()):
        for u, v in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            edges.setdefault((min(u, v), max(u, v)), []).append(k)
    adj: dict[int, list[tuple[int, int, int]]] = {}
    for (u, v), ks in edges.items():
        if len(ks) == 2:
            adj.setdefault(ks[0], []).append((ks[1], u, v))
            adj.setdefault(ks[1], []).append((ks[0], u, v))
    cent = (a + b + c) / 3.0
    seq = _tri_astar(adj, cent, ts, tg, start, goal)
    if seq is None:
        return None
    portals = [(start, start)]
    ccw = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]) > 0
    for k in range(len(seq) - 1):
        u, v = next((u, v) for m, u, v in adj[seq[k]] if m == seq[k + 1])
        # left and right seen in the direction of travel, from the triangle's winding:
        # leaving a counter-clockwise triangle through its edge p -> q, q is on the left
        # (the centroids' direction misjudged it in thin triangles, and the funnel then
        # pulled the path straight through walls)
        t = tri[seq[k]]
        p, q = next((t[i], t[(i + 1) % 3]) for i in range(3) if {t[i], t[(i + 1) % 3]} == {u, v})
        left, right = (q, p) if ccw[seq[k]] else (p, q)
        portals.append((xy[left], xy[right]))
    portals.append((goal, goal))
    path = funnel(portals)
    inside = poly.buffer(ENTRY_INSET_M)
    if inside.covers(shapely.LineString(path)):
        return path
    # never a path out of the free space: the portals' midpoints, shortcut where possible
    mids = [start, *((pl + pr) / 2.0 for pl, pr in portals[1:-1]), goal]
    return _shortcut(np.array(mids), inside)


def _shortcut(pts: np.ndarray, region) -> np.ndarray:
    """The path through ``pts`` with every run of points skipped that a straight segment
    inside ``region`` can replace."""
    out, i = [pts[0]], 0
    while i < len(pts) - 1:
        j = len(pts) - 1
        while j > i + 1 and not region.covers(shapely.LineString([pts[i], pts[j]])):
            j -= 1
        out.append(pts[j])
        i = j
    return np.array(out)


def _locate(a, b, c, p) -> int | None:
    def cr(u, v):
        return (v[:, 0] - u[:, 0]) * (p[1] - u[:, 1]) - (v[:, 1] - u[:, 1]) * (p[0] - u[:, 0])

    d1, d2, d3 = cr(a, b), cr(b, c), cr(c, a)
    inside = ((d1 >= -1e-12) & (d2 >= -1e-12) & (d3 >= -1e-12)) | (
        (d1 <= 1e-12) & (d2 <= 1e-12) & (d3 <= 1e-12)
    )
    k = np.nonzero(inside)[0]
    return int(k[0]) if len(k) else None


def _tri_astar(adj, cent, s, g, start, goal):
    tie = itertools.count()
    best = {s: 0.0}
    parent = {}
    heap = [(0.0, next(tie), s)]
    closed = set()
    while heap:
        _, _, n = heapq.heappop(heap)
        if n == g:
            out = [n]
            while out[-1] != s:
                out.append(parent[out[-1]])
            return out[::-1]
        if n in closed:
            continue
        closed.add(n)
        here = start if n == s else cent[n]
        for m, _, _ in adj.get(n, ()):
            there = goal if m == g else cent[m]
            cost = best[n] + float(np.hypot(*(there - here)))
            if cost < best.get(m, math.inf):
                best[m] = cost
                parent[m] = n
                heapq.heappush(heap, (cost + float(np.hypot(*(goal - there))), next(tie), m))
    return None


def _cross(o, a, b) -> float:
    return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))


def funnel(portals: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """The simple stupid funnel algorithm: taut path through (left, right) portals.

    The first portal is (start, start), the last (goal, goal)."""
    apex = portals[0][0]
    left, right = portals[0]
    ai = li = ri = 0
    out = [apex]
    i = 1
    while i < len(portals):
        pl, pr = portals[i]
        # tighten the right side (right means clockwise of the apex direction)
        if _cross(apex, right, pr) >= 0:  # pr is left of (or on) apex->right: narrower
            if np.array_equal(apex, right) or _cross(apex, left, pr) < 0:
                right, ri = pr, i
            else:  # right crossed over left: left becomes a path corner
                out.append(left)
                apex, ai = left, li
                left = right = apex
                li = ri = ai
                i = ai + 1
                continue
        if _cross(apex, left, pl) <= 0:  # pl is right of (or on) apex->left: narrower
            if np.array_equal(apex, left) or _cross(apex, right, pl) > 0:
                left, li = pl, i
            else:
                out.append(right)
                apex, ai = right, ri
                left = right = apex
                li = ri = ai
                i = ai + 1
                continue
        i += 1
    if not np.array_equal(out[-1], portals[-1][0]):
        out.append(portals[-1][0])
    return np.array(out)


def _dedupe(pts: np.ndarray) -> np.ndarray:
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = np.hypot(*np.diff(pts, axis=0).T) > 1e-9
    return pts[keep]


def path_clearance(points: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> float:
    """Smallest distance between a polyline and a set of segments."""
    if len(points) < 2 or len(starts) == 0:
        return math.inf
    line = shapely.LineString(points)
    segs = shapely.linestrings(np.stack([starts, ends], axis=1))
    tree = shapely.STRtree(segs)
    near = tree.query(line, predicate="dwithin", distance=5.0)
    if len(near) == 0:
        return math.inf
    return float(shapely.distance(line, segs[near]).min())
