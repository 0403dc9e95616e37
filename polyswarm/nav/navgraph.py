"""Topological graph of a PolyMap for a robot of radius r (thesis chapter 4).

* a node per convex piece of each cell's partition (``polyswarm.polymap.partition``);
* an edge across each shared sector vector, from the partition's own bookkeeping:
  inside a cell the split records which two pieces it joins; across a cell border the
  pieces are matched by interval overlap along the border line, which is known exactly
  from the cell index (the hyperplane of Algorithm 4) - never by comparing coordinates;
* pruning for radius r: the robot's disc must keep r from obstacle vectors and
  ``frontier_radius`` (at most r) from frontier vectors. A frontier is not a wall (the
  thesis, section 2: "frontiers are not obstacles, but may be treated as such"): what
  lies beyond it is unseen, and the local controller keeps its distance from whatever
  the live scan shows there. With the full r, a door seen at an angle showed only a
  wedge of the room behind it, bounded by two frontier vectors from its jambs, with no
  room for the disc: no robot could enter (procedural worlds: missions ended at 43-98 %).
  A node stays when some point of it (its centroid or a point of one of its openings)
  has that clearance, an edge when a part of the shared opening has (an opening
  narrower than 2r has none).
* tight passages: an opening with room for the disc at ``tight_radius`` (the robot's
  radius and the map's wall error) but not at r is an edge too, ``tight``, costing
  ``TIGHT_PENALTY_M`` more. The procedural office's doors are 0.7 m wide in the clear,
  8 cm wider than a 0.3 m clearance needs; the mapped jambs' noise closed them in the
  graph, and a robot that had slipped into a room (a jamb still a frontier) was shut in
  (in-process office runs: missions ended at 83-99 %).
* incremental: ``update(map, changed_cells)`` recomputes only those cells and their
  neighbours (obstacles near a border change clearance on both sides).

    graph = NavGraph.build(pmap, radius=0.25, frontier_radius=0.1)
    graph = graph.update(new_map, delta_cells)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from polyswarm.config import NavConfig
from polyswarm.polymap import (
    BORDER_TOL_M,
    CellIndex,
    GridPolyMap,
    VectorType,
    point_segment_distance,
)
from polyswarm.polymap.partition import partition_of

NodeId = tuple[int, int, int]  # cell i, cell j, piece index
PORTAL_STEP_M = 0.05  # openings are checked for clearance at this spacing
# what the robot's disc keeps its distance from (obstacles: radius; frontiers: frontier_radius)
BOUNDARY = (VectorType.OBSTACLE, VectorType.FRONTIER)
BUFFER_SEGMENTS = 4  # quarter-circle segments of the planner's grown obstacles
SAMPLE_SLACK_M = 0.005  # openings are sampled: keep this much extra clearance
# a tight passage (room at the tight radius only) counts as this much longer, so a way
# with the full clearance is taken unless it is longer by more than this
TIGHT_PENALTY_M = 5.0


def grown_radius(radius: float) -> float:
    """The planner grows obstacles by a polygon circumscribing the radius (so a path is
    never closer than the radius); the graph prunes with the same reach plus the
    sampling slack, so an edge it keeps is one the planner can pass."""
    return radius / math.cos(math.pi / (4 * BUFFER_SEGMENTS))


@dataclass(frozen=True)
class Portal:
    """The usable part of an opening between two nodes (clearance >= r along it; a
    ``tight`` one has only the graph's ``tight_radius``)."""

    a: np.ndarray
    b: np.ndarray
    tight: bool = False

    @property
    def mid(self) -> np.ndarray:
        return 0.5 * (self.a + self.b)

    @property
    def width(self) -> float:
        return float(np.hypot(*(self.b - self.a)))


@dataclass
class CellGraph:
    nodes: dict[NodeId, np.ndarray]  # node -> a point of it with clearance (for A*)
    internal: dict[tuple[NodeId, NodeId], Portal]  # edges inside the cell
    all_pieces: int = 0


@dataclass(frozen=True)
class GraphPatch:
    """Cells and borders of a graph recomputed by an update (None: gone)."""

    cells: dict[CellIndex, CellGraph | None]
    borders: dict[tuple[CellIndex, CellIndex], dict | None]


@dataclass
class NavGraph:
    radius: float  # metres kept from obstacle vectors
    cell_size: float
    cells: dict[CellIndex, CellGraph] = field(default_factory=dict)
    borders: dict[tuple[CellIndex, CellIndex], dict[tuple[NodeId, NodeId], Portal]] = field(
        default_factory=dict
    )
    frontier_radius: float | None = None  # metres kept from frontier vectors (None: radius)
    tight_radius: float | None = None  # metres kept from obstacles in a tight passage

    def __post_init__(self) -> None:
        if self.frontier_radius is None:
            self.frontier_radius = self.radius
        if self.tight_radius is None:
            self.tight_radius = self.radius
        if not 0.0 <= self.frontier_radius <= self.radius:
            raise ValueError("frontier_radius must be within [0, radius]")
        if not 0.0 < self.tight_radius <= self.radius:
            raise ValueError("tight_radius must be within (0, radius]")

    # -- construction -------------------------------------------------------------------

    @classmethod
    def build(
        cls,
        pmap: GridPolyMap,
        radius: float,
        frontier_radius: float | None = None,
        tight_radius: float | None = None,
    ) -> NavGraph:
        g = cls(radius, pmap.cell_size, frontier_radius=frontier_radius, tight_radius=tight_radius)
        g._recompute(pmap, set(pmap.cells))
        return g

    @classmethod
    def for_robot(cls, pmap: GridPolyMap, nav: NavConfig) -> NavGraph:
        """The graph of ``pmap`` with the clearances of ``nav``."""
        return cls.build(
            pmap, nav.obstacle_clearance_m, nav.frontier_clearance_m, nav.tight_clearance_m
        )

    def update(self, pmap: GridPolyMap, changed: set[CellIndex] | frozenset) -> NavGraph:
        """The graph after ``changed`` cells of ``pmap`` changed (in place; returns self).

        Only the changed cells and the borders they share are recomputed. A neighbour's
        clearance within r of that border may be stale until it changes itself; paths
        stay safe because the planner checks the exact map (``Planner``).
        """
        self._recompute(pmap, set(changed))
        return self

    def _recompute(self, pmap: GridPolyMap, cells: set[CellIndex]) -> None:
        """Recompute ``cells`` and the borders they share, in one vectorised pass."""
        live = sorted(c for c in cells if c in pmap.cells)
        for c in cells - set(live):
            self.cells.pop(c, None)
        pairs = set()
        for i, j in cells:
            for n in ((i + 1, j), (i, j + 1), (i - 1, j), (i, j - 1)):
                pairs.add(((i, j), n) if (i, j) < n else (n, (i, j)))
        live_pairs = sorted(p for p in pairs if p[0] in pmap.cells and p[1] in pmap.cells)
        for p in pairs - set(live_pairs):
            self.borders.pop(p, None)

        # 1. every opening to check: splits inside each cell, each piece's stretch of the
        #    cell border, and the shared intervals across each border
        jobs = _Openings()
        centroids = []
        for c in live:
            part = partition_of(pmap.cells[c])
            for pa, pb, a, b in part.internal_links():
                jobs.add(("link", c, (pa, pb)), a, b)
            for k, _, a, b in _border_segments(pmap.cells[c]):
                jobs.add(("side", c, k), a, b)
            centroids.extend(p.centroid for p in part.pieces)
        for pair in live_pairs:
            for key, a, b in _border_intervals(pmap, *pair):
                jobs.add(("border", pair, key), a, b)

        # 2. one clearance test of all their samples (and the piece centroids): the
        #    radius from obstacles (a tight passage: the tight radius), the frontier
        #    radius from frontiers
        reach = grown_radius(self.radius) + SAMPLE_SLACK_M
        reach_t = grown_radius(self.tight_radius) + SAMPLE_SLACK_M
        reach_f = grown_radius(self.frontier_radius) + SAMPLE_SLACK_M
        (so, eo), (sf, ef) = _boundary_around(pmap, live, reach)
        centroids = np.array(centroids, dtype=float).reshape(-1, 2)
        pts, first, n = jobs.samples()
        every = np.concatenate([centroids, pts])
        d_obstacle = clearance(every, so, eo, reach)
        tight_ok = d_obstacle >= reach_t
        if self.frontier_radius > 0:
            tight_ok[tight_ok] = clear_of(every[tight_ok], sf, ef, reach_f)
        wide_ok = tight_ok & (d_obstacle >= reach)
        centre_ok = tight_ok[: len(centroids)]
        portals = _longest_runs(pts, wide_ok[len(centroids) :], first, n)
        if self.tight_radius < self.radius:  # openings with room at the tight radius only
            tight = _longest_runs(pts, tight_ok[len(centroids) :], first, n, tight=True)
            portals = [p if p is not None else t for p, t in zip(portals, tight, strict=True)]

        # 3. assemble nodes and edges
        fresh = {c: CellGraph({}, {}, len(partition_of(pmap.cells[c]).pieces)) for c in live}
        k = 0
        for c in live:
            cg = fresh[c]
            for piece in range(cg.all_pieces):
                if centre_ok[k]:
                    cg.nodes[(c[0], c[1], piece)] = centroids[k]
                k += 1
        for pair in live_pairs:
            self.borders[pair] = {}
        for (kind, where, key), portal in zip(jobs.keys, portals, strict=True):
            if portal is None:
                continue
            if kind == "border":
                self.borders[where][key] = portal
                continue
            cg = fresh[where]
            # a piece whose centroid is too close may still hold a usable opening
            if kind == "link":
                a, b = (where[0], where[1], key[0]), (where[0], where[1], key[1])
                cg.internal[(a, b)] = portal
                cg.nodes.setdefault(a, portal.mid)
                cg.nodes.setdefault(b, portal.mid)
            else:
                cg.nodes.setdefault((where[0], where[1], key), portal.mid)
        self.cells.update(fresh)

    def patch(self, changed: set[CellIndex]) -> GraphPatch:
        """The part of the graph an ``update(map, changed)`` recomputed: those cells and
        the borders they share (None: gone), for ``apply`` on a copy elsewhere."""
        pairs = {
            ((i, j), n) if (i, j) < n else (n, (i, j))
            for i, j in changed
            for n in ((i + 1, j), (i, j + 1), (i - 1, j), (i, j - 1))
        }
        return GraphPatch(
            {c: self.cells.get(c) for c in changed}, {p: self.borders.get(p) for p in pairs}
        )

    def apply(self, patch: GraphPatch) -> NavGraph:
        """A ``patch`` of an identical graph applied (in place; returns self)."""
        for c, cg in patch.cells.items():
            if cg is None:
                self.cells.pop(c, None)
            else:
                self.cells[c] = cg
        for p, portals in patch.borders.items():
            if portals is None:
                self.borders.pop(p, None)
            else:
                self.borders[p] = portals
        return self

    # -- queries ------------------------------------------------------------------------

    @property
    def node_count(self) -> int:
        return sum(len(c.nodes) for c in self.cells.values())

    @property
    def piece_count(self) -> int:
        return sum(c.all_pieces for c in self.cells.values())

    @property
    def edge_count(self) -> int:
        return sum(len(c.internal) for c in self.cells.values()) + sum(
            len(b) for b in self.borders.values()
        )

    def has_node(self, node: NodeId) -> bool:
        cg = self.cells.get((node[0], node[1]))
        return cg is not None and node in cg.nodes

    def point(self, node: NodeId) -> np.ndarray:
        return self.cells[(node[0], node[1])].nodes[node]

    def neighbours(self, node: NodeId):
        """(neighbour, portal) pairs of a node."""
        i, j, _ = node
        cg = self.cells.get((i, j))
        if cg is None:
            return
        for (a, b), p in cg.internal.items():
            if a == node:
                yield b, p
            elif b == node:
                yield a, Portal(p.b, p.a, p.tight)
        for n in ((i + 1, j), (i, j + 1), (i - 1, j), (i, j - 1)):
            key = ((i, j), n) if (i, j) < n else (n, (i, j))
            for (a, b), p in self.borders.get(key, {}).items():
                if a == node:
                    yield b, p
                elif b == node:
                    yield a, Portal(p.b, p.a, p.tight)


# ---------------------------------------------------------------------------------------


def _cell_boundary(cell) -> tuple:
    """((starts, ends) of obstacle vectors, (starts, ends) of frontier vectors) of one
    cell, cached on the (immutable) cell."""
    cached = cell.__dict__.get("_nav_boundary")
    if cached is None:
        st, en, ty = cell.vectors
        cached = tuple((st[ty == int(kind)], en[ty == int(kind)]) for kind in BOUNDARY)
        cell.__dict__["_nav_boundary"] = cached
    return cached


def _boundary_around(pmap: GridPolyMap, cells, reach: float) -> tuple:
    """Obstacle and frontier vectors (as ``_cell_boundary``) of the cells and of every
    cell within ``reach`` of them."""
    k = 1 + int(reach // pmap.cell_size)
    near = {
        (i + di, j + dj) for i, j in cells for di in range(-k, k + 1) for dj in range(-k, k + 1)
    }
    parts = [_cell_boundary(pmap.cells[c]) for c in near if c in pmap.cells]
    z = np.zeros((0, 2))
    return tuple(
        (
            np.concatenate([z, *(p[kind][0] for p in parts)]),
            np.concatenate([z, *(p[kind][1] for p in parts)]),
        )
        for kind in range(len(BOUNDARY))
    )


def clear_of(points: np.ndarray, st: np.ndarray, en: np.ndarray, radius: float) -> np.ndarray:
    """For each point: is it at least ``radius`` from every segment st[k]-en[k]?"""
    return clearance(points, st, en, radius) >= radius


def clearance(points: np.ndarray, st: np.ndarray, en: np.ndarray, reach: float) -> np.ndarray:
    """For each point: its distance to the nearest segment st[k]-en[k], or ``reach`` if
    none is closer than that.

    Spatial hashing in numpy: each segment is registered in the bins (of side
    ``reach``) that its bounding box grown by ``reach`` covers; a point is tested
    exactly against the segments registered in its own bin only."""
    out = np.full(len(points), float(reach))
    if len(st) == 0 or len(points) == 0:
        return out
    b = max(reach, 0.05)  # metres; bins smaller than 5 cm only add registrations
    lo = np.floor((np.minimum(st, en) - reach) / b).astype(np.int64)
    hi = np.floor((np.maximum(st, en) + reach) / b).astype(np.int64)
    origin = lo.min(axis=0)
    lo, hi = lo - origin, hi - origin
    width = int(hi[:, 1].max()) + 1
    nx, ny = hi[:, 0] - lo[:, 0] + 1, hi[:, 1] - lo[:, 1] + 1
    count = nx * ny
    seg = np.repeat(np.arange(len(st)), count)
    local = np.arange(len(seg)) - np.repeat(np.cumsum(count) - count, count)
    key = (lo[seg, 0] + local // ny[seg]) * width + lo[seg, 1] + local % ny[seg]
    order = np.argsort(key, kind="stable")
    key, seg = key[order], seg[order]
    pb = np.floor(points / b).astype(np.int64) - origin
    inside = (pb[:, 1] >= 0) & (pb[:, 1] < width) & (pb[:, 0] >= 0)
    pkey = np.where(inside, pb[:, 0] * width + pb[:, 1], -1)
    left = np.searchsorted(key, pkey, "left")
    m = np.where(inside, np.searchsorted(key, pkey, "right") - left, 0)
    if m.sum() == 0:
        return out
    pidx = np.repeat(np.arange(len(points)), m)
    sidx = seg[np.repeat(left, m) + np.arange(len(pidx)) - np.repeat(np.cumsum(m) - m, m)]
    a, d = st[sidx], en[sidx] - st[sidx]
    rel = points[pidx] - a
    t = np.clip(
        np.einsum("ij,ij->i", rel, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-18), 0, 1
    )
    gap = rel - t[:, None] * d
    dist = np.sqrt(np.einsum("ij,ij->i", gap, gap))
    has = m > 0  # pidx is sorted: each point's candidates are one run
    out[has] = np.minimum(out[has], np.minimum.reduceat(dist, (np.cumsum(m) - m)[has]))
    return out


class _Openings:
    """Openings to test, each sampled every PORTAL_STEP_M."""

    def __init__(self) -> None:
        self.keys: list = []
        self.a: list = []
        self.b: list = []

    def add(self, key, a, b) -> None:
        self.keys.append(key)
        self.a.append(a)
        self.b.append(b)

    def samples(self):
        a = np.array(self.a, dtype=float).reshape(-1, 2)
        b = np.array(self.b, dtype=float).reshape(-1, 2)
        L = np.hypot(*(b - a).T)
        n = np.maximum(3, np.ceil(L / PORTAL_STEP_M).astype(np.int64) + 1)
        owner = np.repeat(np.arange(len(a)), n)
        first = np.cumsum(n) - n
        t = (np.arange(len(owner)) - first[owner]) / (n[owner] - 1)
        return a[owner] + t[:, None] * (b - a)[owner], first, n


def _longest_runs(pts, ok, first, n, tight: bool = False) -> list[Portal | None]:
    """For each opening: its longest run of usable samples, or None."""
    out: list[Portal | None] = [None] * len(first)
    if len(pts) == 0:
        return out
    owner = np.repeat(np.arange(len(first)), n)
    # a run starts at a usable sample whose predecessor is unusable or another opening's
    prev_ok = np.r_[False, ok[:-1]] & np.r_[False, owner[1:] == owner[:-1]]
    next_ok = np.r_[ok[1:], False] & np.r_[owner[1:] == owner[:-1], False]
    starts = np.nonzero(ok & ~prev_ok)[0]
    stops = np.nonzero(ok & ~next_ok)[0]  # inclusive, paired with starts in order
    keep = stops > starts  # a single usable sample is a pinch point, not an opening
    starts, stops = starts[keep], stops[keep]
    if len(starts) == 0:
        return out
    length = stops - starts
    order = np.lexsort((-length, owner[starts]))  # per opening, the longest run first
    first_of = np.r_[True, np.diff(owner[starts][order]) != 0]
    for k in order[first_of].tolist():
        out[int(owner[starts[k]])] = Portal(pts[starts[k]].copy(), pts[stops[k]].copy(), tight)
    return out


SECTOR = int(VectorType.SECTOR)


def _border_segments(cell) -> list:
    """Sector vectors of the cell's pieces lying on its border: (piece, side, start, end).

    side: 0 west, 1 east, 2 south, 3 north. Cached on the (immutable) cell."""
    cached = cell.__dict__.get("_border_segments")
    if cached is not None:
        return cached
    owner, xy, nxt, types, links = partition_of(cell).vectors
    cand = (types == SECTOR) & (links < 0)
    x0, y0, x1, y1 = cell.bounds
    out = []
    for side, (axis, val) in enumerate(((0, x0), (0, x1), (1, y0), (1, y1))):
        on = (
            cand
            & (np.abs(xy[:, axis] - val) <= BORDER_TOL_M)
            & (np.abs(nxt[:, axis] - val) <= BORDER_TOL_M)
        )
        out.extend((int(owner[i]), side, xy[i], nxt[i]) for i in np.nonzero(on)[0])
    cell.__dict__["_border_segments"] = out
    return out


def _border_intervals(pmap: GridPolyMap, a: CellIndex, b: CellIndex):
    """(edge key, start, end) of the shared openings of two neighbouring cells (a < b).

    The border line is known from the cell indices; the pieces' border stretches are
    matched by interval overlap along it."""
    if a[0] != b[0]:  # b is east of a: the border is the line x = b.i * size
        side_a, side_b, axis = 1, 0, 1
    else:  # b is north of a
        side_a, side_b, axis = 3, 2, 0
    sa = [s for s in _border_segments(pmap.cells[a]) if s[1] == side_a]
    sb = [s for s in _border_segments(pmap.cells[b]) if s[1] == side_b]
    out = []
    for ka, _, pa, qa in sa:
        lo_a, hi_a = sorted((pa[axis], qa[axis]))
        for kb, _, pb, qb in sb:
            lo, hi = max(lo_a, min(pb[axis], qb[axis])), min(hi_a, max(pb[axis], qb[axis]))
            if hi - lo <= 1e-9:
                continue
            p0, p1 = np.empty(2), np.empty(2)
            p0[axis], p1[axis] = lo, hi
            p0[1 - axis] = p1[1 - axis] = pa[1 - axis]
            out.append((((a[0], a[1], ka), (b[0], b[1], kb)), p0, p1))
    return out


def node_of(pmap: GridPolyMap, x: float, y: float) -> NodeId | None:
    loc = pmap.locate(x, y)
    return None if loc is None else (loc[0][0], loc[0][1], loc[1])


def nodes_of(pmap: GridPolyMap, xy: np.ndarray) -> list[NodeId | None]:
    """``node_of`` for many points at once."""
    return [None if loc is None else (*loc[0], loc[1]) for loc in pmap.locate_many(xy)]


def piece_polygon(pmap: GridPolyMap, node: NodeId) -> np.ndarray:
    return partition_of(pmap.cells[(node[0], node[1])]).pieces[node[2]].xy


def clearance_at(pmap: GridPolyMap, xy: np.ndarray, reach: float = 2.0) -> np.ndarray:
    """Distance to the nearest obstacle vector for each point (search within reach)."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    out = np.full(len(xy), math.inf)
    for k, p in enumerate(xy):
        st, en, _ = pmap.vectors([VectorType.OBSTACLE], pmap.cells_within(p[0], p[1], reach))
        if len(st):
            out[k] = float(point_segment_distance(p, st, en).min())
    return out
