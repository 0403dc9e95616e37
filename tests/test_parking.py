"""Idle robots wait out of passages while frames are pending (``polyswarm.parking``,
``agents.parking``), on two rooms joined by a door, checkable by hand."""

from __future__ import annotations

import numpy as np
import shapely

from polyswarm.config import Config
from polyswarm.parking import blocks_passage, park_clearance_m, parking_spots
from polyswarm.polymap import GridPolyMap, Ring, TypedPolygon, VectorType
from protocols.messages import AssignmentKind, Pose

# two 4 m x 4 m rooms side by side, walls 0.2 m thick at x = 4.0-4.2, a door 1 m wide
# (y = 1.5-2.5) through it
FLAT = np.array(
    [
        (0, 0), (4, 0), (4, 1.5), (4.2, 1.5), (4.2, 0), (8.2, 0), (8.2, 4), (4.2, 4),
        (4.2, 2.5), (4, 2.5), (4, 4), (0, 4),
    ],
    dtype=float,
)  # fmt: skip
DOOR = (4.1, 2.0)


def _flat() -> GridPolyMap:
    ring = Ring(FLAT, [VectorType.OBSTACLE] * len(FLAT))
    return GridPolyMap(2.0).merge(TypedPolygon(ring)).map


def test_a_robot_in_the_door_blocks_it_and_spots_are_clear_of_walls():
    clear = park_clearance_m(Config().nav)
    assert abs(clear - 0.8) < 1e-9  # 0.2 m radius, twice 0.3 m of planning clearance
    pmap = _flat()
    assert blocks_passage(pmap, DOOR, clear)  # 0.5 m from the jambs
    assert not blocks_passage(pmap, (2.0, 2.0), clear)  # a room's middle: 2 m from walls
    pts = parking_spots(pmap, DOOR, clear)
    assert len(pts) > 10
    walls = shapely.Polygon(FLAT).exterior
    assert all(walls.distance(shapely.Point(p)) >= clear - 1e-9 for p in pts)
    assert all(shapely.Polygon(FLAT).contains(shapely.Point(p)) for p in pts)
    d = np.hypot(*(pts - DOOR).T)
    assert (np.diff(d) >= -1e-9).all()  # nearest first


def _coordinator(pose):
    from agents.coordinator import Coordinator

    coord = Coordinator(Config(), {"r1": tuple(pose)})
    coord.on_robot_map("r1", _flat())
    coord.flush()
    coord.on_alive("r1", True)
    coord.on_pose("r1", 1.0, Pose(*pose))
    return coord


def _cycles(coord, n=5):
    for step in range(2, 2 + n):
        coord.now = float(step)
        coord.cycle()


def test_an_idle_robot_in_the_door_moves_out_while_a_frame_is_pending():
    coord = _coordinator((*DOOR, 0.0))
    coord.frames_pending = ("r2",)  # r2 explores in a frame of its own
    _cycles(coord)
    a = coord.robots["r1"].assignment
    assert a is not None and a.kind == AssignmentKind.EXPLORE
    assert not blocks_passage(coord.merged, a.goal, park_clearance_m(Config().nav))
    assert np.hypot(a.goal[0] - DOOR[0], a.goal[1] - DOOR[1]) < 2.0  # the nearest spot


def test_no_parking_without_pending_frames_or_out_of_passages():
    told = _coordinator((*DOOR, 0.0))  # every frame known: nothing changes
    _cycles(told)
    a = told.robots["r1"].assignment
    assert a is None or a.kind != AssignmentKind.EXPLORE
    roomy = _coordinator((2.0, 2.0, 0.0))
    roomy.frames_pending = ("r2",)
    _cycles(roomy)
    a = roomy.robots["r1"].assignment
    assert a is None or a.kind != AssignmentKind.EXPLORE
