"""A robot out of every coordinator's reach picks frontiers of its own map
(agents/alone.py), on maps drawn by hand."""

from __future__ import annotations

import numpy as np

from agents.alone import ALONE_AFTER_S, PEER_WARY_M, Alone
from polyswarm.explore.targets import Sensor
from polyswarm.nav.navgraph import NavGraph
from polyswarm.polymap import GridPolyMap
from protocols.messages import Assignment, AssignmentKind, RobotState
from tests.conftest import F, O, rect

SENSOR = Sensor(range_m=3.5, fov_rad=2 * np.pi)


def corridor():
    """A 8 m x 2 m corridor open at both ends: a frontier at x = 0.5 and one at x = 8.5."""
    pmap = GridPolyMap(2.0).merge(rect(0.5, 0.5, 8.5, 2.5, (O, F, O, F))).map
    return pmap, NavGraph.build(pmap, 0.2)


def always(goal):
    return object()  # a path


def test_alone_only_once_a_coordinator_was_alive_and_has_been_gone_a_while():
    a = Alone()
    assert not a.active(100.0)  # never heard of one (starting up): waits for it
    a.coordinator("coordinator", True, 0.0)
    a.coordinator("coordinator", False, 10.0)
    assert not a.active(10.0 + ALONE_AFTER_S - 0.1)
    assert a.active(10.0 + ALONE_AFTER_S)
    a.coordinator("coordinator", True, 20.0)
    assert not a.active(30.0)


def test_wants_a_target_when_idle_waiting_or_done_exploring_but_not_when_sent_home():
    a = Alone()
    a.coordinator("c", True, 0.0)
    a.coordinator("c", False, 0.0)
    t = ALONE_AFTER_S
    explore = Assignment(AssignmentKind.EXPLORE, 4, (1.0, 1.0))
    home = Assignment(AssignmentKind.HOME, 5, (1.0, 1.0))
    assert a.wants_target(t, RobotState.IDLE, None)
    assert a.wants_target(t, RobotState.REACHED, explore)
    assert not a.wants_target(t, RobotState.NAVIGATING, explore)
    assert not a.wants_target(t, RobotState.REACHED, home)
    wait = Assignment(AssignmentKind.STOP, -1)  # no target for it when it was cut off
    assert a.wants_target(t, RobotState.IDLE, wait)


def test_the_nearest_open_frontier_and_ids_of_its_own():
    own, graph = corridor()
    a = Alone()
    got = a.choose(own, graph, None, SENSOR, np.array([7.5, 1.5]), [], always, None)
    assert got is not None and got.target == -2 and got.goal[0] > 4.0  # the east end
    again = a.choose(own, graph, None, SENSOR, np.array([7.5, 1.5]), [], always, got)
    # the east frontier was looked at (done): the west one next, with the next id
    assert again is not None and again.target == -3 and again.goal[0] < 4.0


def test_frontiers_others_explored_or_near_another_robot_are_left_out():
    own, graph = corridor()
    xy = np.array([7.5, 1.5])
    # the merged map it last had holds the space past the east end: explored by others
    merged = GridPolyMap(2.0).merge(rect(0.5, 0.5, 12.0, 2.5, (O, O, O, F))).map
    got = Alone().choose(own, graph, merged, SENSOR, xy, [], always, None)
    assert got is not None and got.goal[0] < 4.0
    # another robot was last seen at the west end: nothing left for this one
    peer = np.array([0.5 + PEER_WARY_M / 2, 1.5])
    assert Alone().choose(own, graph, merged, SENSOR, xy, [peer], always, None) is None


def test_a_target_without_a_path_is_not_chosen():
    own, graph = corridor()
    a = Alone()
    got = a.choose(own, graph, None, SENSOR, np.array([7.5, 1.5]), [], lambda g: None, None)
    assert got is None and len(a.done) == 2  # both tried, both remembered
