"""The grid baselines of the navigation bench (polyswarm/gridplan.py) on grids whose
shortest paths are known."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from polyswarm.grids.occupancy import FREE, OCCUPIED, OccupancyGrid
from polyswarm.nav.gridplan import grid_astar, grid_mcp, inflated


def length(cells) -> float:
    return sum(math.dist(a, b) for a, b in itertools.pairwise(cells))


def test_both_planners_go_round_a_wall_by_the_same_shortest_8_connected_path():
    trav = np.ones((50, 50), dtype=bool)
    trav[10:40, 25] = False  # a wall across the middle, open above and below
    fast = grid_mcp(trav, (25, 5), (25, 45))
    slow, _ = grid_astar(trav, (25, 5), (25, 45))
    # round the wall's end at row 9 or 40: 15 diagonal steps over, the same back, and
    # 10 straight: 10 + 30 * sqrt(2)
    assert length(fast) == pytest.approx(10 + 30 * math.sqrt(2))
    assert length(slow) == pytest.approx(length(fast))
    assert all(trav[c] for c in fast) and fast[0] == (25, 5) and fast[-1] == (25, 45)


def test_no_path_through_a_closed_wall_and_none_from_a_blocked_cell():
    trav = np.ones((20, 20), dtype=bool)
    trav[:, 10] = False
    assert grid_mcp(trav, (5, 2), (5, 18)) is None
    assert grid_mcp(trav, (5, 10), (5, 18)) is None


def test_inflation_keeps_the_radius_from_anything_not_free():
    data = np.full((21, 21), FREE, dtype=np.int8)
    data[10, 10] = OCCUPIED
    trav = inflated(OccupancyGrid(data, 0.1), 0.25)
    # a cell is kept when its centre is 0.25 m from the occupied cell's edge (centre
    # distance less half a cell): 0.3 m, three cells along the row, is the nearest kept
    assert not trav[10, 8:13].any() and trav[10, 7] and trav[10, 13]
