"""Occupancy grid <-> PolyMap.

``grid_to_polymap`` is Algorithm 1 of the thesis: a vector at every border between a
free cell and a non-free one (obstacle if the neighbour is occupied, frontier if it is
unknown or off the map), chained into rings with free space on the left, collinear
vectors merged. Beyond the thesis, staircases that fit a straight line within
``diagonal_tolerance_px`` become one diagonal vector. Polygons made only of frontiers
(isolated specks of free space) are dropped, as in thesis 5.2.

``polymap_to_grid`` rasterises: a cell is free if its centre is in explored space,
occupied if it lies within ``wall_thickness_m`` behind an obstacle vector, else unknown.
A PolyMap stores no wall thickness, so the rasteriser has to be told one.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import shapely

from polyswarm.errors import DataFormatError
from polyswarm.grids.occupancy import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from polyswarm.polymap import GridPolyMap, Ring, TypedPolygon, VectorType

log = logging.getLogger(__name__)

# direction codes of axis-aligned grid vectors
_DIRS = np.array([(1, 0), (0, 1), (-1, 0), (0, -1)], dtype=np.int64)


def grid_to_polygons(
    grid: OccupancyGrid, diagonal_tolerance_px: float = 0.25, min_diagonal_steps: int = 4
) -> list[TypedPolygon]:
    """Algorithm 1: typed polygons (with holes) of the free space of ``grid``."""
    free = grid.free
    rows, cols = free.shape
    occ = np.pad(grid.occupied, 1, constant_values=False)
    fr = np.pad(free, 1, constant_values=False)
    runs = []  # (start_x, start_y, end_x, end_y, direction, type) in corner units
    # neighbour offsets (dr, dc) for bottom, right, top, left borders of a free cell
    for d, (dr, dc) in enumerate(((-1, 0), (0, 1), (1, 0), (0, -1))):
        nb_free = fr[1 + dr : 1 + dr + rows, 1 + dc : 1 + dc + cols]
        nb_occ = occ[1 + dr : 1 + dr + rows, 1 + dc : 1 + dc + cols]
        r, c = np.nonzero(free & ~nb_free)
        t = np.where(nb_occ[r, c], VectorType.OBSTACLE, VectorType.FRONTIER).astype(np.int64)
        runs.append(_runs(r, c, t, d))
    runs = np.concatenate(runs)
    rings = _chain(runs)
    log.debug("grid %dx%d: %d runs, %d rings", rows, cols, len(runs), len(rings))
    polys = _assemble(rings, diagonal_tolerance_px, min_diagonal_steps)
    # corner units -> metres
    res, (ox, oy) = grid.resolution, grid.origin
    out = []
    for shell, holes in polys:
        if all((t == VectorType.FRONTIER).all() for _, t in [shell, *holes]):
            continue  # an isolated speck of free space, bounded only by frontiers
        conv = [Ring(np.array([ox, oy]) + xy * res, t) for xy, t in [shell, *holes]]
        out.append(TypedPolygon(conv[0], tuple(conv[1:])))
    return out


def _runs(r: np.ndarray, c: np.ndarray, t: np.ndarray, d: int) -> np.ndarray:
    """Merge unit vectors on one side of free cells into maximal runs of one type."""
    if len(r) == 0:
        return np.zeros((0, 6), dtype=np.int64)
    horizontal = d in (0, 2)
    line, pos = (r, c) if horizontal else (c, r)
    order = np.lexsort((pos, t, line))
    line, pos, t = line[order], pos[order], t[order]
    brk = np.ones(len(line), dtype=bool)
    brk[1:] = (line[1:] != line[:-1]) | (pos[1:] != pos[:-1] + 1) | (t[1:] != t[:-1])
    first = np.nonzero(brk)[0]
    last = np.append(first[1:], len(line)) - 1
    ln, p0, p1, ty = line[first], pos[first], pos[last] + 1, t[first]
    # corner coordinates (x, y) of run start and end, free cell on the left
    if d == 0:  # bottom border, running +x at y = row
        sx, sy, ex, ey = p0, ln, p1, ln
    elif d == 1:  # right border, running +y at x = col + 1
        sx, sy, ex, ey = ln + 1, p0, ln + 1, p1
    elif d == 2:  # top border, running -x at y = row + 1
        sx, sy, ex, ey = p1, ln + 1, p0, ln + 1
    else:  # left border, running -y at x = col
        sx, sy, ex, ey = ln, p1, ln, p0
    return np.stack([sx, sy, ex, ey, np.full_like(sx, d), ty], axis=1)


def _chain(runs: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Follow runs end-to-start into closed rings; at a pinch point turn left."""
    by_start: dict[tuple[int, int], list[int]] = {}
    for k, (sx, sy) in enumerate(runs[:, :2].tolist()):
        by_start.setdefault((sx, sy), []).append(k)
    used = np.zeros(len(runs), dtype=bool)
    rings = []
    data = runs.tolist()
    for k0 in range(len(runs)):
        if used[k0]:
            continue
        verts, types = [], []
        k = k0
        while not used[k]:
            used[k] = True
            sx, sy, ex, ey, d, t = data[k]
            verts.append((sx, sy))
            types.append(t)
            cands = [j for j in by_start.get((ex, ey), ()) if not used[j] or j == k0]
            if not cands:
                break
            if len(cands) > 1:  # pinch: prefer left turn, then straight, then right
                pref = {(d + 1) % 4: 0, d: 1, (d + 3) % 4: 2}
                cands.sort(key=lambda j: pref.get(data[j][4], 3))
            k = cands[0]
        for loop_v, loop_t in _split_at_touches(verts, types):
            rings.append((np.array(loop_v, dtype=np.float64), np.array(loop_t, dtype=np.uint8)))
    return rings


def _split_at_touches(verts: list, types: list) -> list[tuple[list, list]]:
    """Cut a ring that passes a vertex twice into simple loops touching at that vertex.

    Turning left at pinch points keeps free cells that touch diagonally apart, but two
    obstacles touching diagonally then leave a figure-eight ring; GEOS wants it as two
    rings touching at a point.
    """
    out = []
    stack_v: list = []
    stack_t: list = []
    seen: dict = {}
    for v, t in zip(verts, types, strict=True):
        if v in seen:
            k = seen[v]
            out.append((stack_v[k:], stack_t[k:]))
            for w in stack_v[k + 1 :]:
                seen.pop(w, None)
            del stack_v[k:], stack_t[k:]
        seen[v] = len(stack_v)
        stack_v.append(v)
        stack_t.append(t)
    out.append((stack_v, stack_t))
    return [(v, t) for v, t in out if len(v) >= 3]


def _signed_area(xy: np.ndarray) -> float:
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _diagonalise(
    xy: np.ndarray, types: np.ndarray, tol: float, min_steps: int
) -> tuple[np.ndarray, np.ndarray]:
    """Replace staircases by a diagonal through their wall-side corners (tol in cells).

    A staircase is a run of same-type unit steps alternating between two directions.
    The diagonal joins its reflex corners (the corners of the non-free cells poking
    into free space), so no part of a non-free cell ever becomes free space: planners
    keep their clearance from the true walls. Free cells along the stair lose at most
    a corner triangle; their centres stay on or inside the free side.
    """
    n = len(xy)
    if n < min_steps + 2 or tol <= 0:
        return xy, types
    vec = np.roll(xy, -1, axis=0) - xy
    dirs = np.sign(vec).astype(np.int64)
    prev = np.roll(vec, 1, axis=0)
    reflex = (prev[:, 0] * vec[:, 1] - prev[:, 1] * vec[:, 0]) < 0  # right turn at vertex k
    keep = np.ones(n, dtype=bool)
    i = 0
    while i < n - 1:
        j = i
        # extend a staircase of vectors i..j: one type, alternating between two axes
        while j + 1 < n and types[j + 1] == types[i]:
            if np.array_equal(dirs[j + 1], dirs[j]):
                break
            if j + 1 - i >= 2 and not np.array_equal(dirs[j + 1], dirs[j - 1]):
                break
            j += 1
        corners = [k for k in range(i + 1, j + 1) if reflex[k]]
        while len(corners) >= min_steps // 2 + 1:
            a, b = xy[corners[0]], xy[corners[-1]]
            ab = b - a
            L = math.hypot(*ab)
            inner = xy[corners[0] : corners[-1] + 1]
            side = (inner[:, 0] - a[0]) * ab[1] - (inner[:, 1] - a[1]) * ab[0]  # >0: right
            if (
                L > 0
                and np.all(np.abs(side[[k - corners[0] for k in corners]]) / L <= tol)
                and np.all(side >= -1e-9)
            ):
                keep[corners[0] + 1 : corners[-1]] = False
                break
            corners = corners[:-1]  # shorten the stair until it fits a line
        i = max(j, i + 1)
    return xy[keep], types[keep]


def _assemble(rings, tol: float, min_steps: int):
    """Group rings into shells with holes; diagonals where they keep rings simple."""
    shells, holes = [], []
    for xy, t in rings:
        if len(xy) < 3:
            continue
        dxy, dt = _diagonalise(xy, t, tol, min_steps)
        if len(dxy) != len(xy) and not shapely.LinearRing(dxy).is_simple:
            dxy, dt = xy, t
        (shells if _signed_area(xy) > 0 else holes).append((dxy, dt, xy, t))
    shell_polys = [shapely.Polygon(s[0]) for s in shells]
    tree = shapely.STRtree(shell_polys)
    areas = np.array([p.area for p in shell_polys])
    attached: list[list] = [[] for _ in shells]
    for h in holes:
        hxy = h[2]
        # a probe just on the free side (left) of the hole's first vector
        d = hxy[1] - hxy[0]
        probe = 0.5 * (hxy[0] + hxy[1]) + 0.25 * np.array([-d[1], d[0]]) / max(np.hypot(*d), 1e-12)
        cand = tree.query(shapely.Point(probe), predicate="intersects")
        if len(cand) == 0:
            log.warning("hole ring without an enclosing free region dropped")
            continue
        attached[int(cand[np.argmin(areas[cand])])].append(h)
    out = []
    for s, hs in zip(shells, attached, strict=True):
        poly = (s[0], s[1]), [(h[0], h[1]) for h in hs]
        if len(s[0]) != len(s[2]) or any(len(h[0]) != len(h[2]) for h in hs):
            check = shapely.Polygon(s[0], [h[0] for h in hs])
            if not check.is_valid:  # diagonals made shell and holes cross: keep the stairs
                poly = (s[2], s[3]), [(h[2], h[3]) for h in hs]
        out.append(poly)
    return out


def grid_to_polymap(
    grid: OccupancyGrid,
    cell_size: float = 2.0,
    diagonal_tolerance_px: float = 0.25,
) -> GridPolyMap:
    """Convert an occupancy grid to a ``GridPolyMap`` (Algorithm 1 plus diagonals)."""
    return GridPolyMap.from_polygons(grid_to_polygons(grid, diagonal_tolerance_px), cell_size)


def polymap_to_grid(
    pmap: GridPolyMap,
    resolution: float,
    like: OccupancyGrid | None = None,
    wall_thickness_m: float = 0.1,
    margin_m: float = 0.5,
) -> OccupancyGrid:
    """Rasterise a PolyMap (on the grid of ``like`` if given)."""
    if like is not None:
        origin, shape = like.origin, like.shape
        resolution = like.resolution
    else:
        if not pmap.cells:
            raise DataFormatError("cannot rasterise an empty map without a target grid")
        x0, y0, x1, y1 = pmap.bounds()
        x0 = math.floor((x0 - margin_m) / resolution) * resolution
        y0 = math.floor((y0 - margin_m) / resolution) * resolution
        shape = (
            math.ceil((y1 + margin_m - y0) / resolution),
            math.ceil((x1 + margin_m - x0) / resolution),
        )
        origin = (x0, y0)
    rows, cols = shape
    data = np.full(shape, UNKNOWN, dtype=np.int8)
    ox, oy = origin
    cs = pmap.cell_size
    for (i, j), cell in pmap.cells.items():
        if not cell.polygons:
            continue
        # pixels whose centres fall in this cell
        c0 = max(0, math.ceil((i * cs - ox) / resolution - 0.5))
        c1 = min(cols, math.ceil(((i + 1) * cs - ox) / resolution - 0.5))
        r0 = max(0, math.ceil((j * cs - oy) / resolution - 0.5))
        r1 = min(rows, math.ceil(((j + 1) * cs - oy) / resolution - 0.5))
        if c0 >= c1 or r0 >= r1:
            continue
        xs = ox + (np.arange(c0, c1) + 0.5) * resolution
        ys = oy + (np.arange(r0, r1) + 0.5) * resolution
        X, Y = np.meshgrid(xs, ys)
        inside = shapely.intersects_xy(cell.region, X, Y)
        block = data[r0:r1, c0:c1]
        block[inside] = FREE
    # walls: cells behind obstacle vectors, up to wall_thickness_m deep
    s, e, _ = pmap.vectors([VectorType.OBSTACLE])
    if len(s):
        d = e - s
        L = np.hypot(d[:, 0], d[:, 1])
        ok = L > 0
        s, d, L = s[ok], d[ok], L[ok]
        u = d / L[:, None]
        right = np.stack([u[:, 1], -u[:, 0]], axis=1)
        step = resolution / 2.0
        n_along = np.ceil((L + resolution) / step).astype(np.int64) + 1
        depths = np.arange(step / 2, max(wall_thickness_m, step / 2) + 1e-9, step)
        idx = np.repeat(np.arange(len(s)), n_along)
        start = np.cumsum(n_along) - n_along
        k = np.arange(len(idx)) - np.repeat(start, n_along)
        t = -resolution / 2 + k * step  # along, from half a cell before to half after
        t = np.minimum(t, L[idx] + resolution / 2)
        base = s[idx] + u[idx] * t[:, None]
        for depth in depths:
            p = base + right[idx] * depth
            cc = np.floor((p[:, 0] - ox) / resolution).astype(np.int64)
            rr = np.floor((p[:, 1] - oy) / resolution).astype(np.int64)
            m = (cc >= 0) & (cc < cols) & (rr >= 0) & (rr < rows)
            rr, cc = rr[m], cc[m]
            notfree = data[rr, cc] != FREE
            data[rr[notfree], cc[notfree]] = OCCUPIED
    return OccupancyGrid(data, resolution, origin)


def round_trip_retention(grid: OccupancyGrid, back: OccupancyGrid) -> tuple[float, float]:
    """Fractions of free and occupied cells of ``grid`` that ``back`` keeps in place."""
    f, o = grid.free, grid.occupied
    free_kept = float((back.data[f] == FREE).mean()) if f.any() else 1.0
    occ_kept = float((back.data[o] == OCCUPIED).mean()) if o.any() else 1.0
    return free_kept, occ_kept
