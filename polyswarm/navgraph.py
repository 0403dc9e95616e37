"""Topological graph of a PolyMap for a robot of radius r (thesis chapter 4).

* a node per convex piece of each cell's partition (``polyswarm.partition``);
* an edge across each shared sector vector, from the partition's own bookkeeping:
  inside a cell the split records which two pieces it joins; across a cell border the
  pieces are matched by interval overlap along the border line, which is known exactly
  from the cell index (the hyperplane of Algorithm 4) - never by comparing coordinates;
* pruning for radius r: the robot's disc must fit inside explored free space, so
  clearance is measured to obstacle *and* frontier vectors (the map does not know what
  lies beyond a frontier). A node stays when some point of it (its centroid or a point
  of one of its openings) has clearance r, an edge when a part of the shared opening
  has (an opening narrower than 2r has none). A goal may lie closer to a frontier.
* incremental: ``update(map, changed_cells)`` recomputes only those cells and their
  neighbours (obstacles near a border change clearance on both sides).

    graph = NavGraph.build(pmap, radius=0.25)
    graph = graph.update(new_map, delta_cells)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from polyswarm.polymap import (
    BORDER_TOL_M,
    CellIndex,
    GridPolyMap,
    VectorType,
    point_segment_distance,
)

NodeId = tuple[int, int, int]  # cell i, cell j, piece index
PORTAL_STEP_M = 0.05  # openings are checked for clearance at this spacing
BOUNDARY = (VectorType.OBSTACLE, VectorType.FRONTIER)  # what the robot's disc must not cross


@dataclass(frozen=True)
class Portal:
    """The usable part of an opening between two nodes (clearance >= r along it)."""

    a: np.ndarray
    b: np.ndarray

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


@dataclass
class NavGraph:
    radius: float
    cell_size: float
    cells: dict[CellIndex, CellGraph] = field(default_factory=dict)
    borders: dict[tuple[CellIndex, CellIndex], dict[tuple[NodeId, NodeId], Portal]] = field(
        default_factory=dict
    )

    # -- construction -------------------------------------------------------------------

    @classmethod
    def build(cls, pmap: GridPolyMap, radius: float) -> NavGraph:
        g = cls(radius, pmap.cell_size)
        g._recompute(pmap, set(pmap.cells))
        return g

    def update(self, pmap: GridPolyMap, changed: set[CellIndex] | frozenset) -> NavGraph:
        """The graph after ``changed`` cells of ``pmap`` changed (in place; returns self).

        Only the changed cells and the borders they share are recomputed. A neighbour's
        clearance within r of that border may be stale until it changes itself; paths
        stay safe because the planner checks the exact map (``Planner``).
        """
        self._recompute(pmap, set(changed))
        return self

    def _recompute(self, pmap: GridPolyMap, cells: set[CellIndex]) -> None:
        for c in cells:
            if c in pmap.cells:
                self.cells[c] = _cell_graph(pmap, c, self.radius)
            else:
                self.cells.pop(c, None)
        pairs = set()
        for i, j in cells:
            for n in ((i + 1, j), (i, j + 1), (i - 1, j), (i, j - 1)):
                pairs.add(((i, j), n) if (i, j) < n else (n, (i, j)))
        for a, b in pairs:
            if a in pmap.cells and b in pmap.cells:
                self.borders[(a, b)] = _border_edges(pmap, a, b, self.radius)
            else:
                self.borders.pop((a, b), None)

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
                yield a, Portal(p.b, p.a)
        for n in ((i + 1, j), (i, j + 1), (i - 1, j), (i, j - 1)):
            key = ((i, j), n) if (i, j) < n else (n, (i, j))
            for (a, b), p in self.borders.get(key, {}).items():
                if a == node:
                    yield b, p
                elif b == node:
                    yield a, Portal(p.b, p.a)


# ---------------------------------------------------------------------------------------


def _boundary_near(pmap: GridPolyMap, c: CellIndex, reach: float):
    i, j = c
    s = pmap.cell_size
    cells = [
        (i + di, j + dj)
        for di in range(-1 - int(reach // s), 2 + int(reach // s))
        for dj in range(-1 - int(reach // s), 2 + int(reach // s))
    ]
    st, en, _ = pmap.vectors(BOUNDARY, cells)
    return st, en


def _clearance(points: np.ndarray, st: np.ndarray, en: np.ndarray) -> np.ndarray:
    """Distance from each point to the nearest obstacle vector (inf if none)."""
    if len(st) == 0 or len(points) == 0:
        return np.full(len(points), math.inf)
    d = en - st
    L2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-18)
    rel = points[:, None, :] - st[None, :, :]
    t = np.clip(np.einsum("pkj,kj->pk", rel, d) / L2[None, :], 0.0, 1.0)
    q = st[None, :, :] + t[:, :, None] * d[None, :, :]
    return np.sqrt(((points[:, None, :] - q) ** 2).sum(-1)).min(axis=1)


def _usable_many(a: np.ndarray, b: np.ndarray, st, en, radius: float) -> list[Portal | None]:
    """For each opening a[k]-b[k]: the longest run of it keeping ``radius`` from the
    boundary (sampled every PORTAL_STEP_M), or None."""
    if len(a) == 0:
        return []
    L = np.hypot(*(b - a).T)
    n = np.maximum(3, np.ceil(L / PORTAL_STEP_M).astype(np.int64) + 1)
    owner = np.repeat(np.arange(len(a)), n)
    first = np.cumsum(n) - n
    t = (np.arange(len(owner)) - first[owner]) / (n[owner] - 1)
    pts = a[owner] + t[:, None] * (b - a)[owner]
    ok = _clearance(pts, st, en) >= radius
    out: list[Portal | None] = []
    for k in range(len(a)):
        seg = ok[first[k] : first[k] + n[k]]
        if not seg.any():
            out.append(None)
            continue
        # longest run of usable samples
        edges = np.diff(np.r_[0, seg.astype(np.int8), 0])
        starts, stops = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]
        r = int(np.argmax(stops - starts))
        p = pts[first[k] : first[k] + n[k]]
        out.append(Portal(p[starts[r]].copy(), p[stops[r] - 1].copy()))
    return out


def _cell_graph(pmap: GridPolyMap, c: CellIndex, radius: float) -> CellGraph:
    cell = pmap.cells[c]
    part = cell.partition
    st, en = _boundary_near(pmap, c, radius)
    links = part.internal_links()
    border = _border_segments(cell)
    a = np.array([np.r_[s_] for _, _, s_, _ in links] + [p for _, _, p, _ in border]).reshape(-1, 2)
    b = np.array([np.r_[e_] for _, _, _, e_ in links] + [q for _, _, _, q in border]).reshape(-1, 2)
    portals = _usable_many(a, b, st, en, radius)
    internal: dict[tuple[NodeId, NodeId], Portal] = {}
    nodes: dict[NodeId, np.ndarray] = {}
    centroids = np.array([p.centroid for p in part.pieces]).reshape(-1, 2)
    clear = _clearance(centroids, st, en)
    for k in np.nonzero(clear >= radius)[0]:
        nodes[(c[0], c[1], int(k))] = centroids[k]
    # pieces whose centroid is too close may still hold a usable opening
    for (pa, pb, _, _), p in zip(links, portals[: len(links)], strict=True):
        if p is not None:
            internal[((c[0], c[1], pa), (c[0], c[1], pb))] = p
            nodes.setdefault((c[0], c[1], pa), p.mid)
            nodes.setdefault((c[0], c[1], pb), p.mid)
    for (k, _, _, _), p in zip(border, portals[len(links) :], strict=True):
        if p is not None:
            nodes.setdefault((c[0], c[1], k), p.mid)
    return CellGraph(nodes, internal, len(part.pieces))


SECTOR = int(VectorType.SECTOR)


def _border_segments(cell) -> list:
    """Sector vectors of the cell's pieces lying on its border: (piece, side, start, end).

    side: 0 west, 1 east, 2 south, 3 north. Cached on the (immutable) cell."""
    cached = cell.__dict__.get("_border_segments")
    if cached is not None:
        return cached
    x0, y0, x1, y1 = cell.bounds
    out = []
    for k, piece in enumerate(cell.partition.pieces):
        xy = piece.xy
        nxt = np.roll(xy, -1, axis=0)
        cand = (piece.types == SECTOR) & (piece.links < 0)
        for side, (axis, val) in enumerate(((0, x0), (0, x1), (1, y0), (1, y1))):
            on = (
                cand
                & (np.abs(xy[:, axis] - val) <= BORDER_TOL_M)
                & (np.abs(nxt[:, axis] - val) <= BORDER_TOL_M)
            )
            for i in np.nonzero(on)[0]:
                out.append((k, side, xy[i], nxt[i]))
    cell.__dict__["_border_segments"] = out
    return out


def _border_edges(pmap: GridPolyMap, a: CellIndex, b: CellIndex, radius: float):
    """Edges between pieces of two neighbouring cells (a < b) across their border."""
    if a[0] != b[0]:  # b is east of a: the border is the line x = b.i * size
        side_a, side_b, axis = 1, 0, 1
    else:  # b is north of a
        side_a, side_b, axis = 3, 2, 0
    sa = [s for s in _border_segments(pmap.cells[a]) if s[1] == side_a]
    sb = [s for s in _border_segments(pmap.cells[b]) if s[1] == side_b]
    if not sa or not sb:
        return {}
    keys, p0s, p1s = [], [], []
    for ka, _, pa, qa in sa:
        lo_a, hi_a = sorted((pa[axis], qa[axis]))
        for kb, _, pb, qb in sb:
            lo, hi = max(lo_a, min(pb[axis], qb[axis])), min(hi_a, max(pb[axis], qb[axis]))
            if hi - lo <= 1e-9:
                continue
            p0, p1 = np.empty(2), np.empty(2)
            p0[axis], p1[axis] = lo, hi
            p0[1 - axis] = p1[1 - axis] = pa[1 - axis]
            keys.append(((a[0], a[1], ka), (b[0], b[1], kb)))
            p0s.append(p0)
            p1s.append(p1)
    if not keys:
        return {}
    st, en = _boundary_near(pmap, a, radius)
    st2, en2 = _boundary_near(pmap, b, radius)
    portals = _usable_many(
        np.array(p0s), np.array(p1s), np.concatenate([st, st2]), np.concatenate([en, en2]), radius
    )
    return {k: p for k, p in zip(keys, portals, strict=True) if p is not None}


def node_of(pmap: GridPolyMap, x: float, y: float) -> NodeId | None:
    loc = pmap.locate(x, y)
    return None if loc is None else (loc[0][0], loc[0][1], loc[1])


def piece_polygon(pmap: GridPolyMap, node: NodeId) -> np.ndarray:
    return pmap.cells[(node[0], node[1])].partition.pieces[node[2]].xy


def clearance_at(pmap: GridPolyMap, xy: np.ndarray, reach: float = 2.0) -> np.ndarray:
    """Distance to the nearest obstacle vector for each point (search within reach)."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    out = np.full(len(xy), math.inf)
    for k, p in enumerate(xy):
        st, en, _ = pmap.vectors([VectorType.OBSTACLE], pmap.cells_within(p[0], p[1], reach))
        if len(st):
            out[k] = float(point_segment_distance(p, st, en).min())
    return out
