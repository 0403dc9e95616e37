"""The reference for maps from real scans: a log-odds grid of the same scans at the same
poses, and the scores of a PolyMap against it, on a room you can draw by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from polyswarm.evaluation.grid_scores import score_against_grid
from polyswarm.grids.logodds import HIT, MISS, LogOddsGrid
from polyswarm.polymap import GridPolyMap, Ring, TypedPolygon, VectorType
from polyswarm.raycast import cast_rays
from polyswarm.slam.scan import LaserScan

O, F = VectorType.OBSTACLE, VectorType.FRONTIER
WALLS = np.array([[0, 0, 4, 0], [4, 0, 4, 3], [4, 3, 0, 3], [0, 3, 0, 0]], dtype=float)


def room_scans(poses, drop=None):
    """720-beam scans of the 4 x 3 m room from ``poses``; beams ``drop`` lost (0.0)."""
    a = -math.pi + np.arange(720) * (2 * math.pi / 720)
    out = []
    for x, y, th in poses:
        r = cast_rays((x, y), a + th, WALLS[:, :2], WALLS[:, 2:], 10.0)
        if drop is not None:
            r = np.where(drop, 0.0, r)
        out.append(LaserScan(r, -math.pi, 2 * math.pi / 720, 0.05, 10.0))
    return out


def room_map(types=(O, O, O, O)) -> GridPolyMap:
    ring = Ring([(0, 0), (4, 0), (4, 3), (0, 3)], list(types))
    return GridPolyMap.from_polygons([TypedPolygon(ring)], 2.0)


POSES = [(1.0, 1.0, 0.0), (3.0, 2.0, 1.0), (2.0, 1.5, -2.0)]


def test_walls_are_occupied_the_room_free_and_a_lost_beam_updates_nothing():
    grid = LogOddsGrid.from_scans(room_scans(POSES), np.array(POSES), out_of_range="zero")
    occ = grid.centres(grid.occupied)
    # every occupied cell lies on a wall (within a cell), the room's inside is free
    d = np.min(np.abs(np.stack([occ[:, 0], occ[:, 0] - 4, occ[:, 1], occ[:, 1] - 3])), axis=0)
    assert (d <= 0.05).all() and len(occ) > 200
    assert grid.free.sum() * grid.resolution**2 == pytest.approx(12.0, rel=0.08)
    assert grid.log_odds.max() <= 3 * HIT + 1e-5 and grid.log_odds.min() >= 5 * MISS
    lost = np.zeros(720, dtype=bool)
    lost[:360] = True  # the beams to y < 1 of one scan without a return
    one = room_scans([POSES[0]], lost)
    grid = LogOddsGrid.from_scans(one, np.array([POSES[0]]), out_of_range="zero")
    touched = grid.centres(grid.touched)
    assert touched[:, 1].min() >= 0.95  # nothing below the sensor: no beam returned there


def test_the_room_mapped_right_scores_full_marks():
    grid = LogOddsGrid.from_scans(room_scans(POSES), np.array(POSES))
    s = score_against_grid(room_map(), grid)
    assert s["wall_recall"] == pytest.approx(1.0)
    assert s["walls_as_frontier"] == 0.0
    assert s["explored_unseen_share"] == 0.0
    assert s["explored_over_free"] == pytest.approx(1.0, abs=0.08)


def test_a_wall_left_open_and_space_nobody_saw_are_counted():
    grid = LogOddsGrid.from_scans(room_scans(POSES), np.array(POSES))
    open_top = score_against_grid(room_map((O, O, F, O)), grid)
    assert open_top["walls_as_frontier"] == pytest.approx(4 / 14, abs=0.05)  # 4 of 14 m
    assert open_top["wall_recall"] == pytest.approx(10 / 14, abs=0.05)
    ring = Ring([(0, 0), (4, 0), (4, 3), (2, 3), (2, 5), (0, 5)], [O, O, O, F, F, O])
    beyond = GridPolyMap.from_polygons([TypedPolygon(ring)], 2.0)  # 2 x 2 m past the wall
    s = score_against_grid(beyond, grid)
    assert s["explored_unseen_m2"] == pytest.approx(2.0 * (2.0 - 0.1 - 0.05), abs=0.3)
    assert s["explored_over_free"] == pytest.approx(16 / 12, abs=0.1)
