"""Obstacles seen and not on the planning map (agents/seen.py), on a map drawn by hand."""

from __future__ import annotations

import numpy as np

from agents.seen import SEEN_KEEP_S, SEEN_RANGE_M, SeenObstacles
from polyswarm.polymap import GridPolyMap, Ring, TypedPolygon
from tests.conftest import O


def room() -> GridPolyMap:
    """A 6 m x 4 m room whose walls the map holds."""
    ring = Ring([(0, 0), (6, 0), (6, 4), (0, 4)], [O] * 4)
    return GridPolyMap(2.0).merge(TypedPolygon(ring)).map


def test_only_close_returns_off_the_map_are_remembered_and_then_forgotten():
    seen = SeenObstacles()
    robot = np.array([3.0, 2.0])
    returns = np.array(
        [
            [3.0, 3.02],  # 0.98 m short of the mapped wall y = 4, and close: kept
            [3.0, 3.99],  # on the mapped wall (1 cm off): explained
            [3.0 + SEEN_RANGE_M + 0.5, 2.0],  # off the map, but too far to matter now
            [2.0, 2.0],  # something in the room, 1 m away: kept
        ]
    )
    assert seen.add(0.0, returns, robot, room()) == 2
    assert {tuple(p) for p in seen.points(1.0)} == {(3.0, 3.02), (2.0, 2.0)}
    # seen again: one point per 5 cm square, its time renewed
    seen.add(SEEN_KEEP_S - 1.0, returns[3:] + 0.001, robot, room())
    assert len(seen) == 2
    assert [tuple(np.round(p, 3)) for p in seen.points(SEEN_KEEP_S + 1.0)] == [(2.001, 2.001)]
    assert len(seen.points(2 * SEEN_KEEP_S)) == 0
