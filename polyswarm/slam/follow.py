"""The map follows the pose graph: after a loop closure moves keyframes, the cells their
old and new placements touch are merged again, from every keyframe that reaches them,
at the keyframes' new poses.

A robot's map is the union of its keyframe polygons placed at their poses. A map that
only grows keeps every pose error made before a loop closed (ghost walls beside the
walls it mapped again; on the ACES log, 58 % of the live map's wall length lies more
than 10 cm from any wall of the map rebuilt at the optimised poses).

The keyframes of a map are kept as they were merged (the polygon a ``MergeOp`` carried,
on the wire's grid, and a frame it is held at), moved by every correction since: an
``Atlas``. A *correction* is a list of (keyframe id, move of its frame); applying it
(``apply_moves``) rebuilds the cells ``C`` that the moved keyframes' old and new
placements touch, from every keyframe of the atlas whose placement reaches ``C`` or its
neighbours (borders are typed against complete neighbours). Cells outside ``C`` stay
bit for bit. Explored space is moved, never deleted: a cell that is empty after the
rebuild is sent as an empty cell.

Applying a correction is a pure function of the map, the atlas and the poses, so a
receiver holding the same atlas (it replayed the same merges) gets the same cells: a
correction goes on the wire as poses, not geometry (``CorrectionOp``), with the digest
of the cells it changed; a receiver whose cells differ fetches the map.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np
import shapely

from polyswarm.errors import DeltaGapError, PolyswarmError
from polyswarm.polymap import (
    PRECISION_M,
    Cell,
    CellIndex,
    GridPolyMap,
    MergeOptions,
    Ring,
    TypedPolygon,
    cells_digest,
    snap_polygon,
)
from polyswarm.se2 import wrap

log = logging.getLogger(__name__)

# content this far from where the graph puts it is moved (ghosts count at 0.1 m). A
# keyframe left where it was keeps its space there, where the map rebuilt at the final
# poses has it elsewhere: at 3 cm, aces and csail (real odometry) followed to IoU 0.985
# and 0.982 of that map; at 1 cm 0.995 and 0.996 (ghost walls 0.8 and 0.9 %); at 0,
# aces 0.997 but every loop closure moved the map (keyframe p95 0.54 s)
MOVE_M = 0.01
REACH_M = 5.0  # a turn counts as the displacement of a point this far out (metres/radian)
# poses on the wire: whole millimetres and 10 microradians (a point 10 m out moves 0.1 mm)
POSE_UNITS_PER_M = 1000
POSE_UNITS_PER_RAD = 100_000

# keyframes merged per pass when cells are rebuilt, when one pass of all of them fails
# (GEOS): the rebuilt cells depend on it, so it is part of the protocol
FALLBACK_BATCH = 8

QPose = tuple[int, int, int]  # a pose in wire units


def quantize_pose(pose) -> QPose:
    """A pose (x, y, theta) in wire units, theta wrapped to [-pi, pi)."""
    x, y, th = (float(v) for v in pose[:3])
    if not math.isfinite(x + y + th):
        raise PolyswarmError(f"pose is not finite: {pose}")
    return (
        round(x * POSE_UNITS_PER_M),
        round(y * POSE_UNITS_PER_M),
        round(float(wrap(th)) * POSE_UNITS_PER_RAD),
    )


def frame_of(polygon: TypedPolygon) -> QPose:
    """Where a merged keyframe polygon is held in an atlas: a frame at its first vertex,
    along x (every end computes it from the polygon alone, so a merge carries no pose;
    the sender tracks the frame as seen from the keyframe's pose)."""
    x, y = polygon.shell.xy[0]
    return (round(float(x) * POSE_UNITS_PER_M), round(float(y) * POSE_UNITS_PER_M), 0)


def pose_of(q: QPose) -> np.ndarray:
    """The pose in metres and radians that wire units ``q`` stand for (every receiver
    computes the same floats)."""
    return np.array([q[0] / POSE_UNITS_PER_M, q[1] / POSE_UNITS_PER_M, q[2] / POSE_UNITS_PER_RAD])


@dataclass(frozen=True)
class CorrectionOp:
    """A map change sent as the poses that made it: moving keyframes by ``moves``
    (keyframe id, the step from its pose in the receiver's atlas to its new pose, in
    wire units; ids ascending) brought the map from ``base_version`` to ``version``
    (always one more), changing the cells ``digest`` hashes."""

    cell_size: float
    base_version: int
    version: int
    moves: tuple[tuple[int, QPose], ...]
    digest: int


def _moved_polygon(poly: TypedPolygon, q0: QPose, q1: QPose) -> TypedPolygon | None:
    """``poly`` (placed at ``q0``) placed at ``q1`` instead, on the 10 um grid; None if it
    collapses there."""
    if q0 == q1:
        return poly
    p0, p1 = pose_of(q0), pose_of(q1)
    d = p1[2] - p0[2]
    c, s = math.cos(d), math.sin(d)

    def move(xy: np.ndarray) -> np.ndarray:
        x, y = xy[:, 0] - p0[0], xy[:, 1] - p0[1]
        return np.stack([c * x - s * y + p1[0], s * x + c * y + p1[1]], axis=1)

    moved = TypedPolygon(
        Ring(move(poly.shell.xy), poly.shell.types),
        tuple(Ring(move(h.xy), h.types) for h in poly.holes),
    )
    return snap_polygon(moved, 1)


class Atlas:
    """The keyframes a map was merged from, each as the polygon it merged (on the
    wire's grid), moved by the corrections since, and its frame (where the polygon is
    held: ``frame_of`` it when merged, moved with it). Both ends of a link keep one per
    robot map: the robot as it merges, the receiver as it replays."""

    def __init__(self) -> None:
        self.polygons: dict[int, TypedPolygon] = {}  # id -> its polygon where it is now
        self.poses: dict[int, QPose] = {}  # id -> its frame
        self.boxes: dict[int, tuple[float, float, float, float]] = {}  # id -> bounding box
        self.options: MergeOptions | None = None  # the merges' options (one per robot)

    def __len__(self) -> int:
        return len(self.polygons)

    def __contains__(self, kid: int) -> bool:
        return kid in self.polygons

    def add(self, kid: int, polygon: TypedPolygon, options: MergeOptions) -> None:
        """Keyframe ``kid``'s merged polygon (a replayed merge), held at ``frame_of`` it."""
        self._place(kid, polygon, frame_of(polygon))
        self.options = options

    def move(self, kid: int, pose: QPose) -> None:
        """Keyframe ``kid``'s frame to ``pose``, its polygon with it (from where it is:
        each move snaps to the 10 um grid again). A polygon that would collapse there (a
        sliver) stays where it is, on every end alike."""
        if self.poses[kid] == pose:
            return
        moved = _moved_polygon(self.polygons[kid], self.poses[kid], pose)
        if moved is None:
            log.info("keyframe %d not moved: its polygon collapses at %s", kid, pose)
            return
        self._place(kid, moved, pose)

    def _place(self, kid: int, polygon: TypedPolygon, pose: QPose) -> None:
        lo, hi = polygon.shell.xy.min(axis=0), polygon.shell.xy.max(axis=0)
        self.polygons[kid], self.poses[kid] = polygon, pose
        self.boxes[kid] = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))

    def copy(self) -> Atlas:
        out = Atlas()
        out.polygons, out.poses, out.boxes = dict(self.polygons), dict(self.poses), dict(self.boxes)
        out.options = self.options
        return out


def choose_moves(atlas: Atlas, poses: dict[int, np.ndarray]) -> dict[int, QPose]:
    """The keyframes whose content (in the atlas) is more than ``MOVE_M`` from where
    ``poses`` (of their atlas frames) put it (a point ``REACH_M`` out counts for a
    turn), with their new poses."""
    out = {}
    for kid, pose in poses.items():
        if kid not in atlas.poses:
            continue
        now = pose_of(atlas.poses[kid])
        d = math.hypot(pose[0] - now[0], pose[1] - now[1])
        turn = abs(float(wrap(pose[2] - now[2])))
        if d + REACH_M * turn > MOVE_M:
            q = quantize_pose(pose)  # theta a step from the old one: no jump of 2 pi
            th = atlas.poses[kid][2] + round(float(wrap(pose[2] - now[2])) * POSE_UNITS_PER_RAD)
            out[kid] = (q[0], q[1], th)
    return out


def largest_move_m(op: CorrectionOp) -> float:
    """How far the correction moves its farthest-moved keyframe (metres; a turn counts
    at ``REACH_M``)."""
    return max(
        (
            math.hypot(dx, dy) / POSE_UNITS_PER_M + REACH_M * abs(dth) / POSE_UNITS_PER_RAD
            for _, (dx, dy, dth) in op.moves
        ),
        default=0.0,
    )


def _minus(a: QPose, b: QPose) -> QPose:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _plus(a: QPose, b: QPose) -> QPose:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def _cells_of(pmap: GridPolyMap, atlas: Atlas, kid: int) -> set[CellIndex]:
    """The cells keyframe ``kid``'s polygon reaches where it is now."""
    box = atlas.boxes[kid]
    i0, j0 = pmap.cell_index(box[0], box[1])
    i1, j1 = pmap.cell_index(box[2], box[3])
    ij = [(i, j) for i in range(i0, i1 + 1) for j in range(j0, j1 + 1)]
    cs = pmap.cell_size
    a = np.array(ij, dtype=float) * cs
    geom = atlas.polygons[kid].to_shapely()
    shapely.prepare(geom)  # one polygon against tens of cells
    hit = shapely.intersects(geom, shapely.box(a[:, 0], a[:, 1], a[:, 0] + cs, a[:, 1] + cs))
    return {ix for ix, h in zip(ij, hit, strict=True) if h}


def apply_moves(
    pmap: GridPolyMap, atlas: Atlas, moves: dict[int, QPose]
) -> tuple[GridPolyMap, list[Cell], dict]:
    """Move keyframes of ``atlas`` (updated in place) and rebuild the cells they touch.

    Returns the map at ``pmap.version + 1``, the cells that changed (the digest's input),
    and what it took. Raises ``PolyswarmError`` for a keyframe the atlas does not hold."""
    t0 = time.perf_counter()
    unknown = [k for k in moves if k not in atlas]
    if unknown:
        raise PolyswarmError(f"correction moves keyframes this map does not hold: {unknown[:5]}")
    if atlas.options is None:
        raise PolyswarmError("correction of a map with no merged keyframes")
    rebuild: set[CellIndex] = set()
    for kid in sorted(moves):
        rebuild |= _cells_of(pmap, atlas, kid)
        atlas.move(kid, moves[kid])
        rebuild |= _cells_of(pmap, atlas, kid)
    fresh, merged = _rebuild_window(pmap, atlas, rebuild) if rebuild else (pmap, 0)
    out, changed = pmap.with_cells_of(fresh, rebuild)
    info = {
        "moved": len(moves),
        "cells": len(changed),
        "keyframes": merged,
        "ms": (time.perf_counter() - t0) * 1e3,
    }
    return out, changed, info


def _rebuild_window(
    pmap: GridPolyMap, atlas: Atlas, rebuild: set[CellIndex]
) -> tuple[GridPolyMap, int]:
    """The cells ``rebuild`` merged afresh from every keyframe reaching them, clipped to
    them and their ring of neighbour cells (the borders are typed against complete
    neighbours); and how many keyframes that took."""
    cs = pmap.cell_size
    ring = sorted({(i + a, j + b) for i, j in rebuild for a in (-1, 0, 1) for b in (-1, 0, 1)})
    ij = np.array(ring, dtype=float) * cs
    area = shapely.union_all(
        shapely.box(ij[:, 0], ij[:, 1], ij[:, 0] + cs, ij[:, 1] + cs), grid_size=PRECISION_M
    )
    shapely.prepare(area)
    box = area.bounds
    near = [
        k
        for k, b in sorted(atlas.boxes.items())
        if b[0] < box[2] and b[2] > box[0] and b[1] < box[3] and b[3] > box[1]
    ]
    geoms = [atlas.polygons[k].to_shapely() for k in near]  # valid: snapped and checked
    hits = shapely.intersects(area, geoms) if near else []
    polys = [atlas.polygons[k] for k, hit in zip(near, hits, strict=True) if hit]
    geoms = [g for g, hit in zip(geoms, hits, strict=True) if hit]
    fresh = GridPolyMap(cs)
    try:  # all at once: one union of overlapping keyframes costs about one merge
        return fresh.merge_many(polys, atlas.options, area, geoms).map, len(polys)
    except PolyswarmError as e:
        log.info("cells merged again in batches: %s", e)
    for k0 in range(0, len(polys), FALLBACK_BATCH):
        batch = slice(k0, k0 + FALLBACK_BATCH)
        try:
            fresh = fresh.merge_many(polys[batch], atlas.options, area, geoms[batch]).map
        except PolyswarmError:
            for poly, geom in zip(polys[batch], geoms[batch], strict=True):
                try:
                    fresh = fresh.merge_many([poly], atlas.options, area, [geom]).map
                except PolyswarmError as e:  # the same on every end of the link
                    log.warning("a keyframe was not merged again: %s", e)
    return fresh, len(polys)


def correct(
    pmap: GridPolyMap, atlas: Atlas, poses: dict[int, np.ndarray]
) -> tuple[GridPolyMap, CorrectionOp | None, dict]:
    """The sender's side: move the keyframes whose ``poses`` moved them, as a
    ``CorrectionOp`` (None when nothing moved)."""
    moves = choose_moves(atlas, poses)
    if not moves:
        return pmap, None, {"moved": 0, "cells": 0, "keyframes": 0, "ms": 0.0}
    steps = {k: _minus(q, atlas.poses[k]) for k, q in moves.items()}
    out, changed, info = apply_moves(pmap, atlas, moves)
    op = CorrectionOp(
        pmap.cell_size,
        pmap.version,
        out.version,
        tuple(sorted(steps.items())),
        cells_digest(changed),
    )
    return out, op, info


def replay_correction(
    pmap: GridPolyMap, atlas: Atlas, op: CorrectionOp
) -> tuple[GridPolyMap, Atlas, list[Cell]]:
    """The receiver's side: ``op`` applied to a bit-identical copy of the sender's map
    and atlas; returns the new map, the new atlas (``atlas`` is not touched) and the
    cells that changed. Raises ``DeltaGapError`` when it does not apply (another
    version, an unknown keyframe, other cells than the sender's): fetch the map."""
    if abs(op.cell_size - pmap.cell_size) > 1e-9:
        raise DeltaGapError(f"correction cell size {op.cell_size} m, map {pmap.cell_size} m")
    if op.base_version != pmap.version or op.version != op.base_version + 1:
        raise DeltaGapError(
            f"correction {op.base_version} -> {op.version} does not apply to version {pmap.version}"
        )
    mine = atlas.copy()
    try:
        moves = {k: _plus(mine.poses[k], d) for k, d in op.moves if k in mine}
        if len(moves) != len(op.moves):
            raise PolyswarmError("it moves keyframes this map does not hold")
        out, changed, _ = apply_moves(pmap, mine, moves)
    except PolyswarmError as e:
        raise DeltaGapError(f"correction does not apply: {e}") from e
    got = cells_digest(changed)
    if got != op.digest:
        raise DeltaGapError(
            f"correction {op.base_version} -> {op.version} gave other cells than the "
            f"sender's (digest {got:08x}, sent {op.digest:08x})"
        )
    return out, mine, changed
