"""Convex partition of a cell's explored space (the role of the BSP in thesis 3.7).

Each cell's explored space (polygons with holes) is triangulated by ear clipping
(mapbox earcut, which returns vertex *indices*) and the triangles are merged into convex
pieces by Hertel-Mehlhorn: a diagonal is removed whenever both of its end vertices stay
convex. The partition keeps its own bookkeeping: every internal split (a sector vector)
records which two pieces it joins, so the navigation graph never compares coordinates
to find neighbours (the numerical problem of thesis 4.1). Sector vectors on the cell
border are joined to the neighbouring cell's pieces by interval overlap along the
border line, which is known exactly from the cell index (the hyperplane of Algorithm 4).

    part = cell.partition            # cached on the cell
    k = part.locate(x, y)            # index of the convex piece holding the point
    part.pieces[k].xy, .types, .links
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass
from functools import cached_property

import mapbox_earcut
import numpy as np
import shapely

from polyswarm.polymap.cells import Cell
from polyswarm.polymap.rings import PRECISION_M, UNITS_PER_M, VectorType

log = logging.getLogger(__name__)

NO_LINK = -1


@dataclass(frozen=True, eq=False)
class Piece:
    """A convex polygon (counter-clockwise) of typed vectors.

    ``links[i]`` is the index of the piece on the other side of vector i when that vector
    is an internal split of the cell, else ``NO_LINK``.
    """

    xy: np.ndarray
    types: np.ndarray
    links: np.ndarray

    @property
    def area(self) -> float:
        x, y = self.xy[:, 0], self.xy[:, 1]
        return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))

    @property
    def centroid(self) -> np.ndarray:
        return self.xy.mean(axis=0)

    def contains(self, x: float, y: float, tol: float = 1e-9) -> bool:
        a = self.xy
        b = np.roll(a, -1, axis=0)
        cross = (b[:, 0] - a[:, 0]) * (y - a[:, 1]) - (b[:, 1] - a[:, 1]) * (x - a[:, 0])
        return bool(np.all(cross >= -tol))


@dataclass(frozen=True, eq=False)
class CellPartition:
    pieces: tuple[Piece, ...]

    @cached_property
    def _edges(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every piece's vectors in one array (start, direction) and each piece's offset."""
        if not self.pieces:
            z = np.zeros((0, 2))
            return z, z, np.zeros(0, dtype=np.int64)
        a = np.concatenate([p.xy for p in self.pieces])
        b = np.concatenate([np.roll(p.xy, -1, axis=0) for p in self.pieces])
        offsets = np.cumsum([0] + [len(p.xy) for p in self.pieces[:-1]])
        return a, b - a, offsets

    def locate(self, x: float, y: float) -> int | None:
        a, d, offsets = self._edges
        if len(a):  # all pieces at once: inside a convex piece is left of all its vectors
            cross = d[:, 0] * (y - a[:, 1]) - d[:, 1] * (x - a[:, 0])
            inside = np.nonzero(np.minimum.reduceat(cross, offsets) >= -1e-9)[0]
            if len(inside):
                return int(inside[0])
        best, best_d = None, np.inf
        for k, p in enumerate(self.pieces):
            # points on a shared vector may miss both pieces by rounding: take the closest
            d = _outside_distance(p.xy, x, y)
            if d < best_d:
                best, best_d = k, d
        return best if best_d <= PRECISION_M else None

    def locate_many(self, xy: np.ndarray) -> np.ndarray:
        """``locate`` for many points: each one's piece index, -1 for none."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        out = np.full(len(xy), -1, dtype=np.int64)
        a, d, offsets = self._edges
        if len(a) and len(xy):
            x, y = xy[:, :1], xy[:, 1:]
            cross = d[:, 0] * (y - a[:, 1]) - d[:, 1] * (x - a[:, 0])  # (points, vectors)
            inside = np.minimum.reduceat(cross, offsets, axis=1) >= -1e-9
            found = inside.any(axis=1)
            out[found] = np.argmax(inside[found], axis=1)
        else:
            found = np.zeros(len(xy), dtype=bool)
        for k in np.nonzero(~found)[0]:  # rare: on a shared vector, or outside
            piece = self.locate(float(xy[k, 0]), float(xy[k, 1]))
            out[k] = -1 if piece is None else piece
        return out

    @cached_property
    def vectors(self) -> tuple[np.ndarray, ...]:
        """All pieces' vectors at once: (piece, start, end, type, link) arrays."""
        if not self.pieces:
            z = np.zeros((0, 2))
            return np.zeros(0, np.int64), z, z, np.zeros(0, np.uint8), np.zeros(0, np.int64)
        sizes = np.array([len(p.xy) for p in self.pieces])
        owner = np.repeat(np.arange(len(self.pieces)), sizes)
        xy = np.concatenate([p.xy for p in self.pieces])
        first = np.repeat(np.cumsum(sizes) - sizes, sizes)
        nxt = xy[first + (np.arange(len(xy)) - first + 1) % sizes[owner]]
        types = np.concatenate([p.types for p in self.pieces])
        links = np.concatenate([p.links for p in self.pieces])
        return owner, xy, nxt, types, links

    def internal_links(self) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
        """Each internal split once: (piece a, piece b, start, end) with a < b."""
        owner, xy, nxt, _, links = self.vectors
        idx = np.nonzero(links > owner)[0]
        return [(int(owner[i]), int(links[i]), xy[i], nxt[i]) for i in idx]


def _outside_distance(xy: np.ndarray, x: float, y: float) -> float:
    a = xy
    b = np.roll(a, -1, axis=0)
    d = b - a
    L = np.hypot(d[:, 0], d[:, 1])
    L = np.where(L > 0, L, 1.0)
    signed = (d[:, 0] * (y - a[:, 1]) - d[:, 1] * (x - a[:, 0])) / L
    return float(max(0.0, -signed.min()))


def partition_of(cell: Cell) -> CellPartition:
    """The cell's convex pieces, computed once per cell object (cells are immutable)."""
    got = cell.__dict__.get("_partition")
    if got is None:
        got = cell.__dict__["_partition"] = partition_cell(cell)
    return got


def partition_cell(cell: Cell) -> CellPartition:
    pieces: list[Piece] = []
    for poly in cell.polygons:
        pieces.extend(_partition_polygon(poly.rings(), offset=len(pieces)))
    return CellPartition(tuple(pieces))


def _triangulate(xy: np.ndarray, ring_ends: np.ndarray, area: float) -> np.ndarray:
    tri = mapbox_earcut.triangulate_float64(xy, ring_ends.astype(np.uint32)).reshape(-1, 3)
    got = _tri_area(xy, tri).sum() if len(tri) else 0.0
    if abs(got - area) <= 1e-6 * max(1.0, area):
        return tri
    # earcut can stumble on holes touching the shell: fall back to GEOS' constrained
    # Delaunay triangulation, mapping its vertices back to indices on the integer grid
    rings = np.split(xy, ring_ends[:-1])
    poly = shapely.Polygon(rings[0], rings[1:])
    tris = shapely.get_parts(shapely.constrained_delaunay_triangles(poly))
    q = np.rint(xy * UNITS_PER_M).astype(np.int64)
    index = {(int(a), int(b)): k for k, (a, b) in enumerate(q)}
    out = []
    for t in tris:
        c = np.rint(shapely.get_coordinates(t)[:3] * UNITS_PER_M).astype(np.int64)
        try:
            out.append([index[(int(a), int(b))] for a, b in c])
        except KeyError:  # pragma: no cover - a Steiner point; cannot happen for CDT
            continue
    return np.array(out, dtype=np.int64).reshape(-1, 3)


def _convex(xy: np.ndarray) -> bool:
    """A counter-clockwise ring turning left (or straight on) at every vertex, on the
    integer grid, with distinct vertices: the triangulation would rebuild it as it is."""
    q = np.rint(xy * UNITS_PER_M).astype(np.int64)
    d = np.concatenate([q[1:], q[:1]]) - q
    e = np.concatenate([d[1:], d[:1]])
    if (d == 0).all(axis=1).any():
        return False
    return bool((d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0] >= 0).all())


def _tri_area(xy: np.ndarray, tri: np.ndarray) -> np.ndarray:
    a, b, c = xy[tri[:, 0]], xy[tri[:, 1]], xy[tri[:, 2]]
    return 0.5 * (
        (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    )


def _partition_polygon(rings, offset: int) -> list[Piece]:
    if len(rings) == 1 and _convex(rings[0].xy):  # already one piece (a common case)
        r = rings[0]
        return [Piece(r.xy.copy(), r.types.copy(), np.full(len(r), NO_LINK, dtype=np.int64))]
    xy = np.concatenate([r.xy for r in rings])
    types = np.concatenate([r.types for r in rings])
    sizes = np.array([len(r) for r in rings])
    ends = np.cumsum(sizes)
    first = np.repeat(ends - sizes, sizes)
    idx = np.arange(len(xy))
    succ = first + (idx - first + 1) % np.repeat(sizes, sizes)  # next vertex on its ring
    nx = xy[succ]
    area = 0.5 * float((xy[:, 0] * nx[:, 1] - xy[:, 1] * nx[:, 0]).sum())
    tri = _triangulate(xy, ends, area)
    if len(tri) == 0:
        return []
    # orient every triangle counter-clockwise
    flip = _tri_area(xy, tri) < 0
    tri[flip] = tri[flip][:, ::-1]
    q = np.rint(xy * UNITS_PER_M).astype(np.int64)  # exact integer geometry for convexity
    # a hole may touch the shell: vertices at one grid point share one index
    key = (q[:, 0] - q[:, 0].min()) * (int(q[:, 1].max() - q[:, 1].min()) + 1) + (
        q[:, 1] - q[:, 1].min()
    )
    _, firsts, inverse = np.unique(key, return_index=True, return_inverse=True)
    canon = firsts[inverse.ravel()]
    tri = canon[tri]
    # type of each boundary vector, keyed by its (start, end) vertex indices
    boundary: dict[tuple[int, int], int] = dict(
        zip(zip(canon.tolist(), canon[succ].tolist(), strict=True), types.tolist(), strict=True)
    )
    cycles = _Cycles(tri, q)
    cycles.join_convex(boundary)
    roots = sorted({cycles.find(t) for t in range(len(tri))})
    local = {r: offset + k for k, r in enumerate(roots)}
    along = {a: b for a, b in boundary}  # boundary vertex -> the next one on its ring
    return [cycles.piece(r, xy, boundary, along, local) for r in roots]


class _Cycles:
    """Triangles as cycles (next/prev maps over vertex indices), joined across
    diagonals while the union stays convex (Hertel-Mehlhorn)."""

    def __init__(self, tri: np.ndarray, q: np.ndarray) -> None:
        self.nxt: list[dict[int, int]] = []
        self.prv: list[dict[int, int]] = []
        self.owner: dict[tuple[int, int], int] = {}  # directed edge -> piece
        for t, (i, j, k) in enumerate(tri.tolist()):
            self.nxt.append({i: j, j: k, k: i})
            self.prv.append({j: i, k: j, i: k})
            for e in ((i, j), (j, k), (k, i)):
                self.owner[e] = t
        self.parent = list(range(len(tri)))
        self.qx, self.qy = q[:, 0].tolist(), q[:, 1].tolist()  # exact Python integers

    def find(self, p: int) -> int:
        parent = self.parent
        while parent[p] != p:
            parent[p] = parent[parent[p]]
            p = parent[p]
        return p

    def _left_turn(self, a: int, b: int, c: int) -> bool:
        qx, qy = self.qx, self.qy
        return (qx[b] - qx[a]) * (qy[c] - qy[b]) - (qy[b] - qy[a]) * (qx[c] - qx[b]) >= 0

    def join_convex(self, boundary: dict) -> None:
        """Drop diagonals, longest first, where the two cycles they split make a convex one."""
        qx, qy, owner, nxt, prv = self.qx, self.qy, self.owner, self.nxt, self.prv
        diagonals = [
            (u, v) for (u, v) in owner if u < v and (v, u) in owner and (u, v) not in boundary
        ]
        diagonals.sort(key=lambda e: -((qx[e[1]] - qx[e[0]]) ** 2 + (qy[e[1]] - qy[e[0]]) ** 2))
        for u, v in diagonals:
            P, Q = self.find(owner[(u, v)]), self.find(owner[(v, u)])
            if P == Q:
                continue
            # merged cycle: P without u->v, Q without v->u; check convexity at u and v
            if not (
                self._left_turn(prv[P][u], u, nxt[Q][u])
                and self._left_turn(prv[Q][v], v, nxt[P][v])
            ):
                continue
            merged_n, merged_p = dict(nxt[P]), dict(prv[P])
            for a, b in nxt[Q].items():
                if a == v:
                    continue
                merged_n[a] = b
                merged_p[b] = a
            merged_n[u] = nxt[Q][u]
            merged_p[nxt[Q][u]] = u
            merged_n[v] = nxt[P][v]
            merged_p[nxt[P][v]] = v
            nxt[P], prv[P] = merged_n, merged_p
            nxt[Q], prv[Q] = {}, {}
            self.parent[Q] = P

    def piece(self, r: int, xy, boundary: dict, along: dict, local: dict) -> Piece:
        """The piece of cycle ``r``: boundary vectors keep their types, splits become
        sectors linked to the piece across (``local``: cycle -> piece number)."""
        nxt, owner = self.nxt[r], self.owner
        start = min(nxt)
        cyc = [start]
        while (w := nxt[cyc[-1]]) != start:
            cyc.append(w)
        verts, ety, links = [], [], []
        for a, b in zip(cyc, cyc[1:] + cyc[:1], strict=True):
            if (a, b) in boundary:
                verts.append(a)
                ety.append(boundary[(a, b)])
                links.append(NO_LINK)
            elif (b, a) in owner:  # an internal split: the piece across owns the reverse
                verts.append(a)
                ety.append(int(VectorType.SECTOR))
                links.append(local[self.find(owner[(b, a)])])
            elif (chain := _boundary_chain(along, a, b)) is not None:
                # collinear boundary vertices whose zero-area triangles the triangulation
                # left out: the vectors between them keep their own types
                for u, v in itertools.pairwise(chain):
                    verts.append(u)
                    ety.append(boundary[(u, v)])
                    links.append(NO_LINK)
            else:  # a degenerate sliver edge: it bounds explored space
                log.warning("partition: edge %s-%s is neither boundary nor split", a, b)
                verts.append(a)
                ety.append(int(VectorType.FRONTIER))
                links.append(NO_LINK)
        return Piece(
            xy=xy[verts].copy(),
            types=np.array(ety, dtype=np.uint8),
            links=np.array(links, dtype=np.int64),
        )


MAX_CHAIN = 64  # collinear boundary vertices looked for along one piece edge


def _boundary_chain(along: dict[int, int], a: int, b: int) -> list[int] | None:
    """Boundary vertices from a to b following the rings (a, ..., b), or None."""
    chain = [a]
    while chain[-1] != b and len(chain) <= MAX_CHAIN:
        w = along.get(chain[-1])
        if w is None:
            return None
        chain.append(w)
    return chain if chain[-1] == b else None
