"""Typing the vectors of merged regions: obstacle where a source obstacle runs,
frontier elsewhere, sector across cell borders; the sensor-noise rules of MergeOptions."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import shapely

from polyswarm.polymap.borders import _border_cover
from polyswarm.polymap.cells import Cell
from polyswarm.polymap.regions import _build_regions, _overlay, _polygon_parts, _region_at
from polyswarm.polymap.rings import (
    BESIDE_ENDS_M,
    BESIDE_STEP_M,
    BORDER_TOL_M,
    CREEP_SHARE,
    MATCH_TOL_M,
    OBSTACLE,
    SECTOR_GAP_M,
    SNAP_ANGLE_DEG,
    UNITS_PER_M,
    CellIndex,
    Ring,
    TypedPolygon,
    VectorType,
    _cross,
    _ring_key,
    _ring_mask,
)


def _typed_cells(
    idxs: list[CellIndex],
    regions: np.ndarray,
    cell_size: float,
    src_starts: np.ndarray,
    src_ends: np.ndarray,
    new_regions: Mapping[CellIndex, shapely.Geometry],
    old_cells: Mapping[CellIndex, Cell],
    obstacle_snap_m: float = 0.0,
    snap_beside_m: tuple[float, float] = (0.0, 0.0),
) -> dict[CellIndex, Cell]:
    """Turn merged cell regions into cells of canonical typed rings.

    Every vector of a result ring is a piece of some input vector (GEOS keeps input
    vertices), so its type is inherited: sector if it lies on the cell border with
    explored space across it; else obstacle if it lies along a source obstacle vector
    (obstacle wins over frontier); else frontier.
    """
    polys, poly_cell = _polygon_parts(regions)
    cell_ij = np.array(idxs, dtype=np.int64).reshape(-1, 2)

    def sectors(a, b, mid, e_owner, types):
        ij = cell_ij[e_owner]
        x0 = ij[:, 0] * cell_size
        y0 = ij[:, 1] * cell_size
        on = lambda v, c: np.abs(v - c) <= BORDER_TOL_M  # noqa: E731
        # per side: vectors on it, the neighbour across, the border line (axis, at)
        cand, nb, axis, line = [], [], [], []
        for side, ax, at, step in (
            (on(a[:, 0], x0) & on(b[:, 0], x0), 0, x0, (-1, 0)),
            (on(a[:, 0], x0 + cell_size) & on(b[:, 0], x0 + cell_size), 0, x0 + cell_size, (1, 0)),
            (on(a[:, 1], y0) & on(b[:, 1], y0), 1, y0, (0, -1)),
            (on(a[:, 1], y0 + cell_size) & on(b[:, 1], y0 + cell_size), 1, y0 + cell_size, (0, 1)),
        ):
            k = np.nonzero(side)[0]
            cand.append(k)
            nb.append(ij[k] + np.array(step))
            axis.append(np.full(len(k), ax))
            line.append(at[k])
        cand = np.concatenate(cand)
        if len(cand) == 0:
            return
        nb, axis, line = np.concatenate(nb), np.concatenate(axis), np.concatenate(line)
        # each neighbour's side once: where its explored space reaches the border
        keys = list(zip(map(tuple, nb.tolist()), axis.tolist(), line.tolist(), strict=True))
        uniq = {key: n for n, key in enumerate(dict.fromkeys(keys))}
        which = np.array([uniq[key] for key in keys])
        first = np.unique(which, return_index=True)[1]
        geoms = [_region_at(key[0], new_regions, old_cells) for key in uniq]
        lo, hi, owner = _border_cover(geoms, axis[first], line[first])
        # explored space across the border along all of the vector but for SECTOR_GAP_M
        # (SECTOR_TOL_M absorbs rounding between the two sides); free space across the
        # border makes a sector even where an obstacle vector once lay on the border:
        # the wall was not there (both sides are free)
        v_lo = np.minimum(a[cand, 1 - axis], b[cand, 1 - axis])
        v_hi = np.maximum(a[cand, 1 - axis], b[cand, 1 - axis])
        n_iv = np.bincount(owner, minlength=len(uniq))
        at_iv = np.concatenate([[0], np.cumsum(n_iv)[:-1]])
        reps = n_iv[which]
        if reps.sum() == 0:
            return
        c = np.repeat(np.arange(len(cand)), reps)  # every (vector, interval across) pair
        iv = np.repeat(at_iv[which] - np.concatenate([[0], np.cumsum(reps)[:-1]]), reps)
        iv += np.arange(len(c))
        over = np.minimum(hi[iv], v_hi[c]) - np.maximum(lo[iv], v_lo[c])
        touch = np.zeros(len(cand), dtype=bool)
        touch[c[over >= 0]] = True
        covered = np.bincount(c, weights=over.clip(0), minlength=len(cand))
        types[cand[touch & (v_hi - v_lo - covered <= SECTOR_GAP_M)]] = VectorType.SECTOR

    out = _typed_polygons(
        polys, poly_cell, src_starts, src_ends, sectors, obstacle_snap_m, snap_beside_m
    )
    cells = [Cell(idxs[k], cell_size, tuple(tp)) for k, tp in out.items() if tp]
    for c, g in zip(cells, _build_regions(cells), strict=True):
        c.__dict__["region"] = g  # fill the cached property in one vectorised pass
    return {c.index: c for c in cells}


def _typed_polygons(
    polys: np.ndarray,
    owner: np.ndarray,
    src_starts: np.ndarray,
    src_ends: np.ndarray,
    sectors=None,
    obstacle_snap_m: float = 0.0,
    snap_beside_m: tuple[float, float] = (0.0, 0.0),
) -> dict[int, list[TypedPolygon]]:
    """Typed, canonical polygons from oriented shapely polygons, grouped by ``owner``.

    Vectors along a source obstacle vector are obstacles (also, with
    ``obstacle_snap_m`` > 0, frontiers running along one within that distance, and with
    ``snap_beside_m`` = (behind, in front) not zero, frontiers lying beside obstacles
    within those distances all along);
    ``sectors(a, b, mid, owner, types)`` may then mark sectors; every other vector is a
    frontier.
    """
    if len(polys) == 0:
        return {}
    rings, ring_poly = shapely.get_rings(polys, return_index=True)
    coords, ring_of = shapely.get_coordinates(rings, return_index=True)
    # vector k runs from coords[k] to coords[k+1] within one ring (rings are closed)
    same = ring_of[1:] == ring_of[:-1]
    a, b = coords[:-1][same], coords[1:][same]
    e_ring = ring_of[:-1][same]
    types = np.full(len(a), VectorType.FRONTIER, dtype=np.uint8)
    tree = _segment_tree(src_starts, src_ends)  # one index of the sources for every test
    obstacle = _obstacle_mask(a, b, src_starts, src_ends, tree, obstacle_snap_m, snap_beside_m)
    types[obstacle] = VectorType.OBSTACLE
    if sectors is not None:
        sectors(a, b, 0.5 * (a + b), owner[ring_poly[e_ring]], types)

    # canonical rings: drop zero-length vectors and collinear vertices between vectors
    # of one type, start each ring at its lowest (x, y) vertex: equal regions give
    # equal rings, whatever the history of merges
    q = np.rint(a * UNITS_PER_M).astype(np.int64)
    keep = _ring_mask(q, e_ring, lambda q, nx, pv: np.any(q != q[nx], axis=1))
    a, q, types, e_ring = a[keep], q[keep], types[keep], e_ring[keep]

    def straight(q, nx, pv):
        u, v = q - q[pv], q[nx] - q
        cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
        dot = u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1]
        return ~((cross == 0) & (dot > 0) & (types == types[pv]))

    keep = _ring_mask(q, e_ring, straight)
    a, q, types, e_ring = a[keep], q[keep], types[keep], e_ring[keep]
    if len(a) == 0:
        return {}
    ring_ids, starts_at, counts = np.unique(e_ring, return_index=True, return_counts=True)
    # rotate each ring to start at its lexicographically lowest vertex
    order = np.lexsort((q[:, 1], q[:, 0], e_ring))
    first = order[np.searchsorted(e_ring[order], ring_ids)]
    s_rep, n_rep = np.repeat(starts_at, counts), np.repeat(counts, counts)
    local = np.arange(len(a)) - s_rep
    perm = s_rep + (local + np.repeat(first - starts_at, counts)) % n_rep
    a, types = a[perm], types[perm]
    x, y = a[:, 0], a[:, 1]
    nxt = s_rep + (local + 1) % n_rep
    area2 = np.add.reduceat(x * y[nxt] - x[nxt] * y, starts_at)

    return _group_rings(a, types, owner, ring_poly[ring_ids], starts_at, counts, area2)


def _group_rings(a, types, owner, poly_of_ring, starts_at, counts, area2) -> dict:
    """Canonical rings (``a``, ``types``; ring r from ``starts_at[r]``, ``counts[r]``
    vertices, twice its signed area ``area2[r]``) as typed polygons grouped by ``owner``
    of their polygon (``poly_of_ring``); a collapsed shell drops its polygon."""
    grouped: dict[int, list[list[Ring]]] = {}
    shell_slot: dict[int, int] = {}
    for r in range(len(starts_at)):
        lo, n = int(starts_at[r]), int(counts[r])
        if n < 3:
            continue
        p = int(poly_of_ring[r])
        plist = grouped.setdefault(int(owner[p]), [])
        ring = Ring(a[lo : lo + n], types[lo : lo + n])
        if p not in shell_slot:  # get_rings lists each polygon's shell first
            if area2[r] <= 0:  # a collapsed shell: the polygon is a sliver
                shell_slot[p] = -1
                continue
            shell_slot[p] = len(plist)
            plist.append([ring])
        elif shell_slot[p] >= 0:
            plist[shell_slot[p]].append(ring)
    out = {}
    for k, plist in grouped.items():
        tp = [TypedPolygon(rs[0], tuple(sorted(rs[1:], key=_ring_key))) for rs in plist]
        tp.sort(key=lambda p: _ring_key(p.shell))
        out[k] = tp
    return out


def _obstacle_mask(
    a: np.ndarray,
    b: np.ndarray,
    src_starts: np.ndarray,
    src_ends: np.ndarray,
    tree: shapely.STRtree | None,
    obstacle_snap_m: float = 0.0,
    snap_beside_m: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Vectors a->b that are obstacles by the source obstacle vectors (``tree`` is their
    ``_segment_tree``): along one, or with the snap distances not zero, running along one
    within ``obstacle_snap_m`` or beside obstacles all along (``_typed_polygons``)."""
    mid = 0.5 * (a + b)
    hit = _along_obstacles(a, b, mid, src_starts, src_ends, tree=tree)
    if obstacle_snap_m > 0:
        front = np.nonzero(~hit)[0]
        near = _along_obstacles(
            a[front],
            b[front],
            mid[front],
            src_starts,
            src_ends,
            obstacle_snap_m,
            SNAP_ANGLE_DEG,
            tree,
            within_ends=True,
        )
        hit[front[near]] = True
    if max(snap_beside_m) > 0:
        front = np.nonzero(~hit)[0]
        beside = _beside_obstacles(
            a[front],
            b[front],
            src_starts,
            src_ends,
            max(snap_beside_m[0], MATCH_TOL_M),
            max(snap_beside_m[1], MATCH_TOL_M),
            SNAP_ANGLE_DEG,
            tree,
        )
        hit[front[beside]] = True
    return hit


def _segment_tree(starts: np.ndarray, ends: np.ndarray) -> shapely.STRtree | None:
    if len(starts) == 0:
        return None
    return shapely.STRtree(shapely.linestrings(np.stack([starts, ends], axis=1)))


def _along_obstacles(
    a,
    b,
    mid,
    src_starts,
    src_ends,
    tol: float = MATCH_TOL_M,
    max_angle_deg: float = 30.0,
    tree: shapely.STRtree | None = None,
    within_ends: bool = False,
    owners: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Vectors a->b lying along a source obstacle vector (within ``tol`` of its line,
    the middle within ``tol`` of the vector), in the same direction (within
    ``max_angle_deg``). With ``within_ends`` neither end may lie past the source's ends
    by more than ``tol``: a frontier that continues a wall's line past the wall's end
    (the view past a door jamb) is not snapped to that wall. ``tree``: the sources'
    ``_segment_tree``, if the caller has it. ``owners`` (one id per vector, one per
    source): only a source of the vector's own id counts (many cells in one call)."""
    hit = np.zeros(len(a), dtype=bool)
    if len(src_starts) == 0 or len(a) == 0:
        return hit
    tree = _segment_tree(src_starts, src_ends) if tree is None else tree
    k, j = tree.query(shapely.points(mid), predicate="dwithin", distance=tol)
    if owners is not None:
        same = owners[0][k] == owners[1][j]
        k, j = k[same], j[same]
    if len(k) == 0:
        return hit
    d = src_ends[j] - src_starts[j]
    L = np.hypot(d[:, 0], d[:, 1])
    n = d / np.where(L > 0, L, 1.0)[:, None]
    da = np.abs(_cross(n, a[k] - src_starts[j]))
    db = np.abs(_cross(n, b[k] - src_starts[j]))
    within = True
    if within_ends:  # both ends' positions along the source, within its extent
        ta = np.einsum("ij,ij->i", a[k] - src_starts[j], n)
        tb = np.einsum("ij,ij->i", b[k] - src_starts[j], n)
        within = (np.minimum(ta, tb) >= -tol) & (np.maximum(ta, tb) <= L + tol)
    u = b[k] - a[k]
    lu = np.hypot(u[:, 0], u[:, 1])
    # same direction within 30 degrees: millimetre-long vectors made by rounding
    # would otherwise match any nearby obstacle
    same_dir = np.einsum("ij,ij->i", u, n) >= np.cos(np.radians(max_angle_deg)) * lu
    ok = (L > 0) & (da <= tol) & (db <= tol) & within & same_dir & (lu > 0)
    hit[np.unique(k[ok])] = True
    return hit


def _beside_obstacles(
    a,
    b,
    src_starts,
    src_ends,
    behind_m: float,
    front_m: float,
    max_angle_deg: float,
    tree: shapely.STRtree | None = None,
) -> np.ndarray:
    """Vectors a->b every point of which (sampled every ``BESIDE_STEP_M``) lies beside a
    source obstacle vector running the same way (within ``max_angle_deg``), at most
    ``behind_m`` behind it (on its unexplored side) or ``front_m`` in front of it. A
    frontier across a doorway is not: its middle lies beside no wall."""
    hit = np.zeros(len(a), dtype=bool)
    if len(src_starts) == 0 or len(a) == 0:
        return hit
    tree = _segment_tree(src_starts, src_ends) if tree is None else tree
    reach = max(behind_m, front_m)
    # only vectors with both ends near some obstacle can lie beside obstacles all along
    ends = shapely.points(np.concatenate([a, b]))
    near = np.zeros(2 * len(a), dtype=bool)
    near[tree.query(ends, predicate="dwithin", distance=reach)[0]] = True
    cand = np.nonzero(near[: len(a)] & near[len(a) :])[0]
    if len(cand) == 0:
        return hit
    u = b[cand] - a[cand]
    lu = np.hypot(u[:, 0], u[:, 1])
    m = np.maximum(1, np.ceil(lu / BESIDE_STEP_M)).astype(int) + 1  # samples, both ends
    v = np.repeat(np.arange(len(cand)), m)
    first = np.cumsum(m) - m
    t = (np.arange(len(v)) - np.repeat(first, m)) / (m[v] - 1)
    pts = a[cand][v] + t[:, None] * u[v]
    k, j = tree.query(shapely.points(pts), predicate="dwithin", distance=reach)
    d = src_ends[j] - src_starts[j]
    L = np.hypot(d[:, 0], d[:, 1])
    n = d / np.where(L > 0, L, 1.0)[:, None]
    rel = pts[k] - src_starts[j]
    side = _cross(n, rel)  # > 0: in front of the obstacle (its explored side)
    along = np.einsum("ij,ij->i", rel, n)
    same_dir = np.einsum("ij,ij->i", u[v[k]], n) >= np.cos(np.radians(max_angle_deg)) * lu[v[k]]
    ok = (
        (L > 0)
        & (side >= -behind_m)
        & (side <= front_m)
        & (along >= -BESIDE_ENDS_M)
        & (along <= L + BESIDE_ENDS_M)
        & same_dir
    )
    covered = np.zeros(len(pts), dtype=bool)
    covered[k[ok]] = True
    hit[cand] = np.logical_and.reduceat(covered, first) & (lu > 0)
    return hit


def fill_notches(cell: Cell, depth_m: float) -> Cell:
    """Remove shallow notches between obstacle vectors: cross-keyframe simplification.

    A wall seen by many keyframes is the union of slightly different fitted lines, so
    its outline is a chain of shallow V's (reflex vertices, measured: half the obstacle
    vectors of a simulated office shorter than 1 cm). A reflex vertex between two
    obstacle vectors, less than ``depth_m`` from the line joining its neighbours and
    not on the cell border, is removed: explored space only grows, by at most
    ``depth_m``, and the wall becomes the straight outer envelope. Repeated to a fixed
    point, so merging the same keyframe again still changes nothing.
    """
    if not (cell.vectors[2] == OBSTACLE).any():
        return cell
    x0, y0, x1, y1 = cell.bounds
    changed = False
    polys = []
    for poly in cell.polygons:
        rings = []
        for ring in poly.rings():
            xy, ty = ring.xy, ring.types
            keep_all = True
            for _ in range(64):  # each pass removes every other candidate
                n = len(xy)
                if n <= 3:
                    break
                prev = np.arange(-1, n - 1)  # -1: the last vertex
                nxt = np.arange(1, n + 1) % n
                u, w = xy[prev], xy[nxt]
                a, b = xy - u, w - xy
                uw = w - u
                L = np.hypot(uw[:, 0], uw[:, 1])
                cand = (
                    (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0] < 0)
                    & (ty == OBSTACLE)
                    & (ty[prev] == OBSTACLE)
                    & (np.abs(_cross(uw, xy - u)) < depth_m * np.where(L > 0, L, 1.0))
                    & (np.abs(xy[:, 0] - x0) > BORDER_TOL_M)
                    & (np.abs(xy[:, 0] - x1) > BORDER_TOL_M)
                    & (np.abs(xy[:, 1] - y0) > BORDER_TOL_M)
                    & (np.abs(xy[:, 1] - y1) > BORDER_TOL_M)
                )
                # never two neighbours in one pass: each removal must see fixed neighbours
                cand[1:] &= ~cand[:-1]
                if cand[0] and cand[-1]:
                    cand[-1] = False
                if not cand.any():
                    break
                xy, ty = xy[~cand], ty[~cand]
                keep_all = False
            filled = ring if keep_all else Ring(xy, ty)
            # a hole thinner than depth_m (a sliver of wall the keyframes saw round) can
            # be left with three vertices running the other way: free space on its
            # right, which every decoder refuses (an agent's journal stopped replaying
            # at such a cell, and with it every later delta); such a ring stays as it was
            if filled.signed_area * ring.signed_area <= 0:
                filled = ring
            changed |= filled is not ring
            rings.append(filled)
        polys.append(TypedPolygon(rings[0], tuple(rings[1:])))
    if not changed:
        return cell
    out = Cell(cell.index, cell.size, tuple(polys), cell.version)
    if not out.region.is_valid or out.area < cell.area - 1e-12:
        return cell  # a removal crossed another part of the outline: keep the teeth
    return out


def _drop_thin_growth(
    old: np.ndarray, new: np.ndarray, width_m: float, walls: list[Cell] | None = None
) -> np.ndarray:
    """Regions that keep ``old`` where all of the growth is thinner than ``width_m``
    and lies along the cell's old walls (``walls``: the old cell of each region, whose
    obstacle vectors count; None: every thin growth is dropped).

    Only cells whose growth is small for their outline can be pure creep along walls
    (area below outline length x width); their growth is tested with a negative
    buffer. Cells that also gained real space keep all of it. Thin growth mostly more
    than ``width_m`` from the old walls fills a pocket between frontiers, not a wall:
    it is kept (a 4 cm sliver left across a door by a keyframe fan cut the room behind
    it off from the robots' navigation graph: the office, 1 robot, seed 3).
    """
    grew = shapely.area(new) - shapely.area(old)
    k = np.nonzero((grew > 0) & (grew <= shapely.length(old) * width_m) & ~shapely.is_empty(old))[0]
    if len(k) == 0:
        return new
    out = new.copy()
    extra, failed = _overlay(shapely.difference, new[k], old[k])
    thin = ~failed & shapely.is_empty(shapely.buffer(extra, -width_m / 2, quad_segs=2))
    if walls is not None and thin.any():
        t = np.nonzero(thin)[0]
        near = np.array([walls[k[j]].wall_zone(width_m) for j in t], dtype=object)
        along, bad = _overlay(shapely.intersection, extra[t], near)
        thin[t] = bad | (shapely.area(along) >= CREEP_SHARE * shapely.area(extra[t]))
    out[k[thin]] = old[k[thin]]
    return out
