"""Standby coordinators' election and the robots' choice of leader (agents/leadership.py)."""

from __future__ import annotations

from agents.leadership import TAKEOVER_S, Following, Leadership, wins
from protocols.messages import Assignment, AssignmentKind, CoordinatorStatus, MissionState


def status(leader: str, term: int) -> CoordinatorStatus:
    return CoordinatorStatus(MissionState.EXPLORING, leader=leader, term=term)


def order(target: int) -> Assignment:
    return Assignment(AssignmentKind.EXPLORE, target, (1.0, 2.0))


def test_the_higher_term_wins_then_the_name_first_in_order():
    assert wins((1, "coordinator2"), (0, "coordinator"))
    assert wins((1, "coordinator"), (1, "coordinator2"))
    assert not wins((0, "coordinator3"), (0, "coordinator2"))


def test_a_standby_takes_over_once_the_active_is_silent_and_no_one_before_it_is_alive():
    lead = Leadership("coordinator2", active=False, since=0.0)
    lead.heard_status(status("coordinator", 0), 10.0)
    lead.heard_assignment("r1", order(41))
    lead.heard_assignment("r2", order(57))
    assert not lead.due(10.0 + TAKEOVER_S - 0.1, set())
    # the active one is silent, but coordinator (first in order) is still alive: wait
    assert not lead.due(10.0 + TAKEOVER_S, {"coordinator", "coordinator2"})
    assert lead.due(10.0 + TAKEOVER_S, {"coordinator2", "coordinator3"})
    lead.take_over(20.0)
    assert lead.active and lead.term == 1
    assert lead.max_target == 57 and set(lead.assignments) == {"r1", "r2"}


def test_two_actives_after_a_partition_settle_on_one():
    old = Leadership("coordinator", active=True)
    new = Leadership("coordinator2", active=True, term=1)
    assert new.heard_status(status("coordinator", 0), 1.0) is False and new.active
    assert old.heard_status(status("coordinator2", 1), 1.0) is True and not old.active


def test_a_robot_follows_the_winner_and_gets_its_held_order_when_it_takes_over():
    f = Following()
    assert f.heard(status("coordinator", 0)) is None  # the first one heard
    assert f.admits("coordinator", order(1))
    assert not f.admits("coordinator2", order(9))  # not the leader: held back
    held = f.heard(status("coordinator2", 1))
    assert held is not None and held.assignment.target == 9
    assert f.heard(status("coordinator", 0)) is None  # the old one, not stepped down yet
    assert not f.admits("coordinator", order(2)) and f.admits("coordinator2", order(10))
