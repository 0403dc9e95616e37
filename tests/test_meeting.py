"""Standpoints of a robot waiting for its frame (``polyswarm.frames.meeting``), on an L-shaped
flat checkable by hand, and the solo coordinator's tour (``agents.meeting``)."""

from __future__ import annotations

import math

import numpy as np
import shapely

from polyswarm.frames.meeting import MEET_NEAR_M, countable, standpoints
from polyswarm.frames.sighting import BODY_M, SEEN_APART_M, WALL_CLEAR_M
from polyswarm.polymap import GridPolyMap, Ring, TypedPolygon, VectorType

# an L: a 10 m x 4 m arm along x, and a 4 m x 8 m arm up from its right end
L_FLAT = np.array([(0, 0), (10, 0), (10, 8), (6, 8), (6, 4), (0, 4)], dtype=float)
OTHER = (2.0, 2.0)  # where the candidate frame puts the other robot: in the long arm


def _flat(types=None) -> GridPolyMap:
    ring = Ring(L_FLAT, types or [VectorType.OBSTACLE] * len(L_FLAT))
    return GridPolyMap(2.0).merge(TypedPolygon(ring)).map


def _solo(pmap: GridPolyMap, pose):
    """A solo coordinator of robot r2, standing at ``pose`` in ``pmap``, its map in."""
    from agents.coordinator import Coordinator
    from polyswarm.config import Config
    from protocols.messages import Pose

    coord = Coordinator(Config(), {"r2": tuple(pose)})
    coord.on_robot_map("r2", pmap)
    coord.flush()
    coord.on_alive("r2", True)
    coord.on_pose("r2", 1.0, Pose(*pose))
    return coord


def test_standpoints_are_in_sight_within_reach_and_off_the_walls():
    pts = standpoints(_flat(), OTHER, [], reach_m=6.0, wall_m=0.35)
    assert len(pts) > 10
    d = np.hypot(*(pts - OTHER).T)
    assert (d >= MEET_NEAR_M - 1e-9).all() and (d <= 6.0 + 1e-9).all()
    assert (np.diff(d) >= -1e-9).all()  # nearest to the other robot first
    flat = shapely.Polygon(L_FLAT)
    assert all(flat.exterior.distance(shapely.Point(p)) >= 0.35 - 1e-9 for p in pts)
    assert all(flat.contains(shapely.Point(p)) for p in pts)
    # the inner corner (6, 4) hides the upper arm's far side from (2, 2): nothing up there
    # lies on the far side of the line from (2, 2) through the corner
    for x, y in pts:
        if y > 4.0:
            assert (x - 2.0) * (4.0 - 2.0) - (y - 2.0) * (6.0 - 2.0) >= -1e-9


def test_standpoints_are_where_the_other_robots_sighting_counts():
    """The sighting test (``polyswarm.frames.sighting.seen_where``) wants the return and a robot's
    width behind it WALL_CLEAR_M from walls: every standpoint keeps its line of sight
    from BODY_M before it to 2 BODY_M past it that far from the flat's walls."""
    pts = standpoints(_flat(), OTHER, [], reach_m=6.0, wall_m=0.35)
    assert len(pts) > 5
    walls = shapely.Polygon(L_FLAT).exterior
    u = (pts - OTHER) / np.hypot(*(pts - OTHER).T)[:, None]
    for k in np.linspace(-1.0, 2.0, 7):
        span = pts + k * BODY_M * u
        assert min(walls.distance(shapely.Point(p)) for p in span) >= WALL_CLEAR_M - 1e-9
    # (4.5, 0.5) is 0.5 m from the wall y = 0 and in sight: a standpoint to drive to,
    # but the line of sight past it reaches 0.19 m from that wall
    st, en = L_FLAT, np.roll(L_FLAT, -1, axis=0)
    assert not countable(np.array([(4.5, 0.5)]), OTHER, st, en)[0]
    assert countable(np.array([(5.0, 2.0)]), OTHER, st, en)[0]


def test_standpoints_fall_back_where_no_sighting_could_count():
    """A corridor 1 m wide leaves no place WALL_CLEAR_M from both walls: the standpoints
    in sight are still offered (the waiting robot may see the other one from there)."""
    corridor = np.array([(0, 0), (12, 0), (12, 1), (0, 1)], dtype=float)
    pmap = GridPolyMap(2.0).merge(TypedPolygon(Ring(corridor, [VectorType.OBSTACLE] * 4))).map
    pts = standpoints(pmap, (1.0, 0.5), [], reach_m=6.0, wall_m=0.35)
    assert len(pts) > 0
    assert not countable(pts, (1.0, 0.5), corridor, np.roll(corridor, -1, axis=0)).any()


def test_standpoints_keep_apart_from_those_visited():
    visited = [(4.5, 2.0), (2.0, 0.5)]
    pts = standpoints(_flat(), OTHER, visited, reach_m=6.0, wall_m=0.35)
    gaps = np.hypot(*(pts[:, None, :] - np.array(visited)[None]).transpose(2, 0, 1))
    assert len(pts) and (gaps >= SEEN_APART_M - 1e-9).all()


def test_no_standpoint_when_the_lidar_reaches_less_than_a_sighting_needs():
    assert len(standpoints(_flat(), OTHER, [], reach_m=MEET_NEAR_M * 0.9)) == 0


def test_a_solo_robot_with_no_frontier_left_tours_standpoints_in_sight_of_the_rendezvous():
    """The solo coordinator of a waiting robot whose map is explored: drawn to a
    rendezvous, it is sent to a standpoint facing it, and after reporting it reached to
    one at least ``SEEN_APART_M`` from the first."""
    from protocols.messages import AssignmentKind, RobotState, RobotStatus

    coord = _solo(_flat(), (8.0, 6.0, 0.0))
    coord.rendezvous = {"r2": OTHER}
    orders = []
    for step in range(2, 40):
        coord.now = float(step)
        out = coord.cycle()
        a = out.assignments.get("r2")
        if a is not None and (not orders or a.target != orders[-1].target):
            orders.append(a)
            coord.on_status("r2", float(step), RobotStatus(RobotState.REACHED, a.target))
        if len(orders) == 2:
            break
    assert len(orders) == 2, orders
    for a in orders:
        assert a.kind == AssignmentKind.EXPLORE and a.frontier == (OTHER,)
        assert MEET_NEAR_M - 1e-9 <= math.dist(a.goal, OTHER) <= 6.0 + 1e-9
    assert math.dist(orders[0].goal, orders[1].goal) >= SEEN_APART_M - 1e-9


def test_a_tour_with_no_standpoint_left_lets_the_solo_coordinator_end():
    """Every standpoint visited: the robot goes home, and is not called back at every
    cycle while the rendezvous stays where it was."""
    from agents.meeting import _Tour
    from protocols.messages import AssignmentKind, MissionState

    coord = _solo(_flat(), (8.0, 6.0, 0.0))
    coord.rendezvous = {"r2": OTHER}
    tour = coord.meetings.tours.setdefault("r2", _Tour())
    tour.visited = [tuple(p) for p in standpoints(_flat(), OTHER, [], 6.0)]  # all of them
    states = []
    for step in range(2, 60):
        coord.now = float(step)
        coord.cycle()
        states.append(coord.state)
    assert MissionState.RETURNING in states
    assert states[-1] in (MissionState.RETURNING, MissionState.DONE)
    assert coord.robots["r2"].assignment.kind == AssignmentKind.HOME


def test_standpoints_lie_where_the_other_robots_lidar_looks():
    """A 270-degree lidar facing +x: nothing in its blind quarter behind it (and 15
    degrees inside the edges); with a full-turn lidar the same place has standpoints."""
    other = (5.0, 2.0, 0.0)
    fov = math.radians(270.0)
    pts = standpoints(_flat(), other, [], reach_m=6.0, wall_m=0.35, fov_rad=fov)
    bearing = np.degrees(np.arctan2(pts[:, 1] - 2.0, pts[:, 0] - 5.0))
    assert len(pts) and (np.abs(bearing) <= 135.0 - 15.0 + 1e-6).all()
    everywhere = standpoints(_flat(), other, [], reach_m=6.0, wall_m=0.35)
    behind = np.degrees(np.arctan2(everywhere[:, 1] - 2.0, everywhere[:, 0] - 5.0))
    assert (np.abs(behind) > 150.0).any()


def _solo_with_a_frontier():
    """A solo coordinator of r2 in the flat whose upper arm's right side is open, and
    the frontier target it sent r2 first."""
    types = [VectorType.OBSTACLE] * len(L_FLAT)
    types[2] = VectorType.FRONTIER  # the upper arm's right side is open
    coord = _solo(_flat(types), (3.0, 2.0, 0.0))
    coord.now = 2.0
    coord.cycle()
    frontier = coord.robots["r2"].assignment
    assert frontier is not None and frontier.frontier != ()  # a frontier target first
    return coord, frontier


def test_a_solo_robot_whose_frontiers_failed_lately_tours_meanwhile():
    """Its one frontier failed (excluded for a while): it is not left standing, it is
    sent to a standpoint; a rendezvous never takes a target it may take."""
    coord, frontier = _solo_with_a_frontier()
    coord.rendezvous = {"r2": OTHER}
    coord.cycle()
    assert coord.robots["r2"].assignment.target == frontier.target  # kept while it may
    coord.robots["r2"].excluded[frontier.target] = math.inf  # it failed there
    coord.robots["r2"].assignment = None
    coord.now = 3.0
    coord.cycle()
    a = coord.robots["r2"].assignment
    assert a is not None and a.frontier == (OTHER,)


def test_a_solo_robot_seen_at_its_candidate_frame_tours_before_its_frontiers():
    """Its frontier is open, but the robots were seen where the candidate frame puts
    them (``tour_first``): it is sent to a standpoint in sight of the rendezvous; once
    that no longer holds, back to its frontier."""
    coord, frontier = _solo_with_a_frontier()
    coord.rendezvous, coord.tour_first = {"r2": OTHER}, {"r2"}
    coord.now = 3.0
    coord.cycle()
    a = coord.robots["r2"].assignment
    assert a is not None and a.frontier == (OTHER,) and a.target != frontier.target
    assert MEET_NEAR_M - 1e-9 <= math.dist(a.goal, OTHER) <= 6.0 + 1e-9
    coord.tour_first = set()
    coord.now = 4.0
    coord.cycle()
    assert coord.robots["r2"].assignment.frontier != (OTHER,)  # its frontier again
