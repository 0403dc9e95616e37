"""The map follows the pose graph: after a loop closure moves keyframes, the cells their
old and new placements touch are merged again, from every keyframe that reaches them,
at the keyframes' current poses.

A robot's map is the union of its keyframe polygons placed at their poses. A map that
only grows keeps every pose error made before a loop closed (ghost walls beside the
walls it mapped again; on the ACES log, 58 % of the live map's wall length lies more
than 10 cm from any wall of the map rebuilt at the optimised poses). Here, a keyframe
whose content in the map is more than ``MOVE_M`` from where its pose now puts it is
*moved*; the cells ``C`` that its old and its new placement touch are rebuilt from the
keyframes (all of them, moved or not) whose placements reach ``C`` or its neighbours
(their borders are typed against complete neighbours). Cells outside ``C`` stay
bit for bit. Explored space is moved, never deleted: a cell that is empty after the
rebuild is sent as an empty cell.

The rebuilt cells go out as an ordinary cell delta, so a receiver's copy follows them
exactly.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from polyswarm.errors import PolyswarmError
from polyswarm.polymap import Cell, CellIndex, GridPolyMap, MergeOptions
from polyswarm.se2 import wrap
from polyswarm.submap import StoredKeyframe, move_polygon

log = logging.getLogger(__name__)

MOVE_M = 0.03  # content this far from its keyframe's pose is moved (ghosts count at 0.1 m)
REACH_M = 5.0  # a turn counts as the displacement of a point this far out (metres/radian)


def moved(merged_at: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Which keyframes' content (placed at ``merged_at``) is more than ``MOVE_M`` from
    their ``poses``."""
    d = np.hypot(*(poses[:, :2] - merged_at[:, :2]).T)
    turn = np.abs(wrap(poses[:, 2] - merged_at[:, 2]))
    return d + REACH_M * turn > MOVE_M


def _cell_range(pmap: GridPolyMap, kf: StoredKeyframe, pose) -> tuple[int, int, int, int]:
    """Cells the keyframe's polygon can touch at ``pose`` (its bounding box's corners)."""
    x0, y0 = kf.polygon.shell.xy.min(axis=0)
    x1, y1 = kf.polygon.shell.xy.max(axis=0)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    cx = np.array([x0, x1, x1, x0])
    cy = np.array([y0, y0, y1, y1])
    wx, wy = pose[0] + c * cx - s * cy, pose[1] + s * cx + c * cy
    i0, j0 = pmap.cell_index(wx.min(), wy.min())
    i1, j1 = pmap.cell_index(wx.max(), wy.max())
    return i0, j0, i1, j1


def _cells(r: tuple[int, int, int, int]) -> set[CellIndex]:
    return {(i, j) for i in range(r[0], r[2] + 1) for j in range(r[1], r[3] + 1)}


def follow(
    pmap: GridPolyMap,
    keyframes: list[StoredKeyframe],
    merged_at: np.ndarray,
    options: MergeOptions,
    batch: int = 8,
) -> tuple[GridPolyMap, np.ndarray, dict]:
    """The map with the cells of moved keyframes merged again; ``merged_at`` updated
    (moved keyframes' content is now at their poses); and what it took."""
    t0 = time.perf_counter()
    poses = np.array([kf.pose for kf in keyframes])
    merged_at = merged_at.copy()
    go = np.flatnonzero(moved(merged_at, poses))
    if len(go) == 0:
        return pmap, merged_at, {"moved": 0, "cells": 0, "keyframes": 0, "ms": 0.0}
    rebuild: set[CellIndex] = set()
    for k in go:
        rebuild |= _cells(_cell_range(pmap, keyframes[k], merged_at[k]))
        rebuild |= _cells(_cell_range(pmap, keyframes[k], poses[k]))
    reach = rebuild | {
        (i + di, j + dj) for i, j in rebuild for di in (-1, 0, 1) for dj in (-1, 0, 1)
    }
    i_lo, j_lo = min(i for i, _ in reach), min(j for _, j in reach)
    i_hi, j_hi = max(i for i, _ in reach), max(j for _, j in reach)
    used = []
    for k, kf in enumerate(keyframes):
        r = _cell_range(pmap, kf, poses[k])
        if r[2] < i_lo or r[0] > i_hi or r[3] < j_lo or r[1] > j_hi:
            continue
        if _cells(r) & reach:
            used.append(k)
    fresh = GridPolyMap(pmap.cell_size)
    polys = [move_polygon(keyframes[k].polygon, poses[k]) for k in used]
    for k0 in range(0, len(polys), batch):
        try:
            fresh = fresh.merge_many(polys[k0 : k0 + batch], options).map
        except PolyswarmError:
            for poly in polys[k0 : k0 + batch]:
                try:
                    fresh = fresh.merge(poly, options).map
                except PolyswarmError as e:  # counted by the caller's map as before
                    log.warning("a keyframe was not merged again: %s", e)
    version = pmap.version + 1
    cells = dict(pmap.cells)
    changed = 0
    for ix in rebuild:
        new = fresh.cells.get(ix)
        old = cells.get(ix)
        if new is None and old is None:
            continue
        if new is not None and old is not None and new.same_content(old):
            continue
        cells[ix] = (new or Cell(ix, pmap.cell_size, ())).with_version(version)
        changed += 1
    merged_at[go] = poses[go]
    out = GridPolyMap(pmap.cell_size, cells, version) if changed else pmap
    info = {
        "moved": len(go),
        "cells": changed,
        "keyframes": len(used),
        "ms": (time.perf_counter() - t0) * 1e3,
    }
    return out, merged_at, info
