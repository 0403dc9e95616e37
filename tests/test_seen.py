"""Obstacles seen and not on the planning map (agents/seen.py), on a map drawn by hand."""

from __future__ import annotations

import numpy as np

from agents.seen import SEEN_KEEP_S, SEEN_RANGE_M, SeenObstacles
from polyswarm.nav.recent import CLEAR_MARGIN_M
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


def _ring_of_returns(centre, radius_m: float, beams: int = 360) -> np.ndarray:
    a = np.linspace(-np.pi, np.pi, beams, endpoint=False)
    return np.asarray(centre) + radius_m * np.column_stack([np.cos(a), np.sin(a)])


def test_a_point_a_later_scan_sees_through_is_forgotten():
    """A robot stood 1 m east of this one (a robot whose frame is unknown cannot be left
    out): remembered. The next scan of a 1-degree lidar sees 1.9 m of free space east
    (the wall x = 4.9 of a room of its own): forgotten. One that sees it at 1 m, or
    sees nothing that way, keeps it; so does one whose returns that way are nearer."""
    robot = np.array([3.0, 2.0])
    body = np.array([[4.0, 2.0], [4.0, 2.12]])

    def remembered(*scans) -> int:
        seen = SeenObstacles()
        seen.add(0.0, body, robot, room())
        for scan in scans:
            seen.forget_seen_through(scan, robot)
        return len(seen)

    assert remembered() == 2
    assert remembered(_ring_of_returns(robot, 1.9)) == 0  # seen through
    assert remembered(_ring_of_returns(robot, 1.0)) == 2  # still there
    at_margin = _ring_of_returns(robot, 1.0 + CLEAR_MARGIN_M / 2)
    assert remembered(at_margin) == 2  # within a return's noise of it
    west = _ring_of_returns(robot, 1.9)
    assert remembered(west[west[:, 0] < robot[0]]) == 2  # no return that way
    occluded = np.vstack([_ring_of_returns(robot, 1.9), [[3.5, 2.0], [3.5, 2.06]]])
    assert remembered(occluded) == 2  # something nearer hides it


def _scan_with_wall(robot, wall_x: float, rng) -> np.ndarray:
    """A 1-degree, 3.5 m lidar's returns (LDS-01 noise: 1 cm + 1.75 % of the range) in
    ``room()`` with an unmapped wall x = ``wall_x`` across it (a wall the merge lost)."""
    a = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    c, s = np.cos(a), np.sin(a)
    d = np.full(len(a), np.inf)
    for axis, at, span in (
        (0, wall_x, 4.0),
        (0, 0.0, 4.0),
        (0, 6.0, 4.0),
        (1, 0.0, 6.0),
        (1, 4.0, 6.0),
    ):
        along, other = (c, s) if axis == 0 else (s, c)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (at - robot[axis]) / along
        cross = robot[1 - axis] + t * other
        hit = (t > 0) & (cross >= 0) & (cross <= span) & (t < d)
        d = np.where(hit, t, d)
    keep = d <= 3.5
    d = d[keep] + rng.normal(0.0, 0.01 + 0.0175 * d[keep])
    return robot + np.column_stack([d * c[keep], d * s[keep]])


def test_a_wall_passed_at_grazing_angles_stays_remembered():
    """A robot drives 3 m along a wall the map lacks, 0.3 m from it. Its returns are
    noisy; one in front of the wall's face seen later at a grazing angle has the wall
    behind it along its bearing, but that is no view through it: the wall it drove past
    stays remembered with no gap it could be routed through (TurtleBot3 office, known
    starts, seed 2: a robot stood 220 s at a wall the merged map had lost)."""
    rng = np.random.default_rng(0)
    seen, m = SeenObstacles(), room()
    for k, y in enumerate(np.arange(0.5, 3.5, 0.05)):
        robot = np.array([4.6, y])
        pts = _scan_with_wall(robot, 4.9, rng)
        seen.forget_seen_through(pts, robot)
        seen.add(0.2 * k, pts, robot, m)
    pts = seen.points(0.2 * k)
    on_wall = np.sort(pts[np.abs(pts[:, 0] - 4.9) < 0.2, 1])
    assert on_wall.min() < 0.5 and on_wall.max() > 3.5  # the stretch driven past
    assert np.diff(on_wall).max() < 0.2  # a TurtleBot3 (0.21 m wide) fits through no gap
