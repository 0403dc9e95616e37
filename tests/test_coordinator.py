"""Frontier assignment (hand-checked) and the coordinator's logic (no transport)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.allocation import EXCLUDE_S, FOLLOW_AFTER_S, REACHED_GRACE_S
from agents.coordinator import END_CONFIRM_CYCLES, Coordinator
from polyswarm.config import Config
from polyswarm.errors import DeltaGapError
from polyswarm.explore.assign import Strategy, assign
from polyswarm.polymap import GridPolyMap, MergeOp, MergeOptions, VectorType, cells_digest
from protocols.mapcodec import (
    decode_any_map,
    decode_merge,
    encode_cells_map,
    encode_merge,
)
from protocols.messages import (
    Assignment,
    AssignmentKind,
    MissionState,
    Pose,
    RobotState,
    RobotStatus,
)
from tests.conftest import F, O, coordinator, corridor_map, feed, rect

INF = math.inf


# --- assignment ----------------------------------------------------------------------------


def test_hungarian_minimises_the_total_cost():
    costs = np.array([[1.0, 10.0], [2.0, 3.0]])
    # both robots are nearest to target 0; the optimum sends robot 1 to target 1 (4 < 12)
    assert assign(Strategy.HUNGARIAN, costs, [0.0, 0.0]) == [0, 1]
    assert assign(Strategy.NEAREST, costs, [0.0, 0.0]) == [0, 0]


def test_nearest_takes_the_nearest_target_whatever_its_utility():
    # target 1 is 2 m farther but borders a big unexplored room (utility 40 m)
    costs = np.array([[3.0, 5.0, 3.0], [4.0, 6.0, 4.0]])
    util = [1.0, 40.0, 2.0]
    assert assign(Strategy.HUNGARIAN, costs[:1], util) == [1]
    # both robots go to the nearest; between the two equally near, the more useful one
    assert assign(Strategy.NEAREST, costs, util) == [2, 2]
    # a robot keeps its target unless another is clearly nearer (hysteresis 0.8)
    assert assign(Strategy.NEAREST, np.array([[3.0, 3.6, 3.0]]), util, [1]) == [1]
    assert assign(Strategy.NEAREST, np.array([[3.0, 3.9, 3.0]]), util, [1]) == [2]


def test_hungarian_sends_one_robot_per_frontier_before_a_second_to_any():
    # targets 0 and 1 are pieces of one frontier (a corridor ahead of both robots),
    # target 2 the only piece of another frontier, farther away
    costs = np.array([[1.0, 2.0, 12.0], [1.5, 1.8, 11.0], [1.1, 2.2, 13.0]])
    util = [4.0, 4.0, 4.0]
    assert assign(Strategy.HUNGARIAN, costs[:2], util) == [0, 1]  # a pack of two
    out = assign(Strategy.HUNGARIAN, costs[:2], util, groups=[7, 7, 9])
    assert sorted(out) == [0, 2] and out[1] == 2  # robot 1 is cheaper to the far one
    # a third robot: no third frontier, so it takes the remaining piece
    out = assign(Strategy.HUNGARIAN, costs, util, groups=[7, 7, 9])
    assert sorted(out) == [0, 1, 2] and out[1] == 2


def test_greedy_discounts_targets_near_a_taken_one():
    costs = np.array([[1.0, 1.5, 6.0], [1.2, 1.6, 4.0]])
    goals = np.array([[0.0, 0.0], [0.5, 0.0], [20.0, 0.0]])
    util = [4.0, 4.0, 4.0]
    out = assign(Strategy.GREEDY, costs, util, goals=goals, separation_m=3.0)
    # robot 0 takes target 0; target 1 beside it loses its utility, so robot 1 goes far
    assert out == [0, 2]


def test_robots_without_a_reachable_target_get_none():
    costs = np.array([[INF, 2.0], [INF, INF]])
    assert assign(Strategy.HUNGARIAN, costs, [1.0, 1.0]) == [1, None]
    assert assign(Strategy.HUNGARIAN, np.zeros((2, 0)), []) == [None, None]


def test_robots_left_over_go_to_their_nearest_target():
    # one target for three robots: robot 0 takes it, robot 1 follows (nearest, and only,
    # target it reaches), robot 2 reaches nothing
    costs = np.array([[INF, 2.0], [INF, 3.0], [INF, INF]])
    assert assign(Strategy.HUNGARIAN, costs, [1.0, 1.0]) == [1, 1, None]
    # two frontiers for three robots: the third goes to the one nearest to it, not to the
    # one the assignment would have given a second robot for its utility
    costs = np.array([[1.0, 9.0], [9.0, 1.0], [2.0, 8.0]])
    assert assign(Strategy.HUNGARIAN, costs, [0.0, 20.0], groups=[0, 1]) == [0, 1, 0]
    # a left-over robot keeps its current target unless another is clearly nearer
    costs = np.array([[1.0, 9.0], [9.0, 1.0], [4.0, 4.5]])
    assert assign(Strategy.HUNGARIAN, costs, [0.0, 0.0], [0, 1, 1], groups=[0, 1]) == [0, 1, 1]
    # ... and only robots allowed to follow do
    followers = [True, True, False]
    assert assign(Strategy.HUNGARIAN, costs, [0.0, 0.0], followers=followers) == [0, 1, None]


def test_hysteresis_keeps_the_current_target_unless_clearly_beaten():
    costs = np.array([[5.0, 4.5]])
    assert assign(Strategy.HUNGARIAN, costs, [0.0, 0.0], current=[0], hysteresis=0.8) == [0]
    costs = np.array([[5.0, 3.0]])
    assert assign(Strategy.HUNGARIAN, costs, [0.0, 0.0], current=[0], hysteresis=0.8) == [1]


# --- the coordinator -------------------------------------------------------------------------


def test_coordinator_sends_one_robot_to_the_frontier_and_ends_when_it_closes():
    c = coordinator(2)
    feed(c, "r1", corridor_map(open_end=True), 0.1)
    out = c.cycle()
    assert out.merged_delta is not None  # the robots' cells were merged
    assert c.state == MissionState.EXPLORING
    kinds = {rid: a.kind for rid, a in out.assignments.items()}
    # one frontier: one robot goes (the nearer one), the other waits
    assert kinds == {"r2": AssignmentKind.EXPLORE}
    goal = np.array(out.assignments["r2"].goal)
    assert 9.0 < goal[0] < 12.0 and 0.0 < goal[1] < 2.0
    # r2 explores the end: the frontier becomes a wall, the mission ends and all go home
    closed = corridor_map(open_end=False)
    feed(c, "r2", closed, 1.0)
    c.now = 1.0
    c.cycle()
    c.now = 1.0 + Config().explore.end_confirm_s
    out = c.cycle()
    # one late cycle is not enough: a loaded coordinator's map may lag the robots
    assert c.state == MissionState.EXPLORING
    cycles = 2
    while c.state == MissionState.EXPLORING and cycles < 10:
        c.now += 0.1
        out = c.cycle()
        cycles += 1
    assert cycles == END_CONFIRM_CYCLES  # cycles in a row without a reachable target
    assert c.state == MissionState.RETURNING
    homes = {rid: a.goal for rid, a in out.assignments.items()}
    assert homes == {"r1": (1.0, 1.0), "r2": (2.0, 1.0)}
    for rid in ("r1", "r2"):
        c.on_status(rid, c.now, RobotStatus(RobotState.HOME, c.robots[rid].assignment.target))
    c.now += 1.0
    out = c.cycle()
    assert c.state == MissionState.DONE
    # every cycle's wall and processor time are kept and the last is in its status
    assert len(c.cycle_cpu_ms) == len(c.cycle_ms) == cycles + 2  # + the first and last
    assert all(
        0.0 <= cpu <= wall + 1.0 for cpu, wall in zip(c.cycle_cpu_ms, c.cycle_ms, strict=True)
    )
    assert out.status.cycle_cpu_ms == c.cycle_cpu_ms[-1]


def test_a_robot_left_over_follows_another_after_a_while():
    c = coordinator(2)
    feed(c, "r1", corridor_map(open_end=True), 0.1)
    c.cycle()
    assert c.robots["r1"].assignment is None  # one frontier: r2 (nearer) goes, r1 waits
    target = c.robots["r2"].assignment.target
    t0 = c.now
    c.now = t0 + FOLLOW_AFTER_S - 1.0
    c.cycle()
    assert c.robots["r1"].assignment is None
    for dt in (FOLLOW_AFTER_S, FOLLOW_AFTER_S + 1.0):  # it follows, and keeps following
        c.now = t0 + dt
        c.on_pose("r2", c.now, Pose(2.0 + dt / 8.0, 1.0, 0.0))  # r2 drives on to the frontier
        c.cycle()
        a = c.robots["r1"].assignment
        assert a.kind == AssignmentKind.EXPLORE and a.target == target
    assert c.robots["r2"].assignment.target == target


def test_a_robot_that_leaves_frees_its_target_and_keeps_its_map():
    c = coordinator(2)
    feed(c, "r2", corridor_map(open_end=True), 0.1)
    c.cycle()
    assert c.robots["r2"].assignment.kind == AssignmentKind.EXPLORE
    area = c.merged.explored_area()
    c.on_alive("r2", False)
    c.now = 2.0
    out = c.cycle()
    assert set(out.assignments) == {"r1"}
    assert c.merged.explored_area() == pytest.approx(area)  # nothing r2 mapped is lost


def on_its_way() -> tuple[Coordinator, Assignment]:
    """One robot, a corridor with an open end, and the robot's assignment to it."""
    c = coordinator(1)
    feed(c, "r1", corridor_map(open_end=True), 0.1)
    c.now = 1.0
    c.cycle()
    return c, c.robots["r1"].assignment


def test_the_mission_does_not_end_while_its_last_target_is_only_excluded():
    c, a = on_its_way()
    c.on_status("r1", c.now, RobotStatus(RobotState.NAVIGATING, a.target))
    c.on_status("r1", c.now, RobotStatus(RobotState.UNREACHABLE, a.target))
    for _ in range(10):  # failed once: excluded for a while, neither sent nor given up
        c.now += 1.0
        out = c.cycle()
        assert c.state == MissionState.EXPLORING
        assert "r1" not in out.assignments or out.assignments["r1"].kind != AssignmentKind.EXPLORE
    c.now += EXCLUDE_S
    out = c.cycle()
    assert out.assignments["r1"].kind == AssignmentKind.EXPLORE  # tried again


def test_a_robot_that_does_not_move_is_stuck_itself_and_the_target_stays_open():
    timeout = Config().explore.no_progress_timeout_s
    c, a = on_its_way()
    # a robot that hands its target back after failing to get free, without having moved:
    # the target is taken from it, and blamed only half
    c.on_status("r1", c.now, RobotStatus(RobotState.STUCK, a.target))
    assert c.failures == {a.target: 0.5} and c.robots["r1"].assignment is None
    c.failures.clear()
    c.now += EXCLUDE_S
    c.cycle()
    a = c.robots["r1"].assignment
    # the robot stands still for longer than the timeout, twice: each time the target is
    # taken from it, and counts half a failure, not enough to blacklist it
    for _ in range(2):
        for _ in range(int(timeout) + 10):
            c.now += 1.0
            c.on_pose("r1", c.now, Pose(1.0, 1.0, 0.0))
            c.cycle()
        c.now += EXCLUDE_S
    assert c.failures.get(a.target, 0) == 1.0 and c.blacklist == []
    c.failures.clear()
    # a robot that drives about without getting closer does fail the target
    c.cycle()
    b = c.robots["r1"].assignment
    for k in range(int(timeout) + 10):
        c.now += 1.0
        c.on_pose("r1", c.now, Pose(1.0 + 0.5 * (k % 4), 1.0 + 0.2 * (k % 3), 0.0))
        c.cycle()
    assert c.failures.get(b.target, 0) == 1


def test_a_target_every_robot_stalls_at_is_given_up_in_the_end():
    """Robots wedged in turn on the way to one target (a way the map shows open and the
    world does not) must not retry it for ever."""
    timeout = Config().explore.no_progress_timeout_s
    c, a = on_its_way()
    for _ in range(4):
        c.cycle()
        if c.blacklist:
            break
        for _ in range(int(timeout) + 10):
            c.now += 1.0
            c.on_pose("r1", c.now, Pose(1.0, 1.0, 0.0))
            c.cycle()
            if c.blacklist:
                break
        c.now += EXCLUDE_S
    assert c.failures[a.target] == 2.0 and c.blacklist  # after four stalls


def test_a_robot_stuck_on_its_way_home_lets_the_mission_end():
    c = coordinator(1)
    feed(c, "r1", corridor_map(open_end=False), 0.1)  # explored: nothing left to see
    c.now = 1.0
    c.cycle()
    c._end_exploration([c.robots["r1"]])
    home = c.robots["r1"].assignment
    assert home.kind == AssignmentKind.HOME
    c.on_status("r1", c.now, RobotStatus(RobotState.NAVIGATING, home.target))
    c.on_status("r1", c.now, RobotStatus(RobotState.STUCK, home.target))
    c.now += 1.0
    c.cycle()
    assert c.state == MissionState.DONE


def test_a_reached_target_is_judged_on_the_map_the_robot_saw():
    c, a = on_its_way()
    seen = corridor_map(open_end=True).merge(rect(0.0, 2.0, 2.0, 4.0, (O, O, O, O))).map
    c.on_status("r1", 1.0, RobotStatus(RobotState.REACHED, a.target))
    # the robot stood and looked (its pose says its map is at the newer version), but the
    # delta with what it saw has not arrived: the target is not blamed yet
    c.on_pose("r1", 1.0 + REACHED_GRACE_S, Pose(10.0, 1.0, 0.0, map_version=seen.version))
    for _ in range(3):
        c.now += 1.0
        c.cycle()
    assert c.failures == {}
    assert c.robots["r1"].assignment.target == a.target
    # its map arrives: the frontier is still open, so now it counts as a failure
    feed(c, "r1", seen, 5.0)
    c.now += 1.0
    c.cycle()
    assert c.failures == {a.target: 1}
    assert c.looks == {a.target: 1} and c.blacklist == []
    # a second look, once the robot may take the target again, leaves it open too
    # (explore.blacklist_after_looks = 2): it is given up
    c.now += EXCLUDE_S
    c.cycle()
    again = c.robots["r1"].assignment
    assert again is not None and again.target == a.target
    c.on_status("r1", c.now, RobotStatus(RobotState.NAVIGATING, a.target))
    c.on_status("r1", c.now, RobotStatus(RobotState.REACHED, a.target))
    c.on_pose("r1", c.now + REACHED_GRACE_S, Pose(10.0, 1.0, 0.0, map_version=seen.version))
    c.now += REACHED_GRACE_S + 1.0
    c.cycle()
    assert c.looks == {a.target: 2}
    assert any(np.allclose(b, a.goal) for b in c.blacklist)


def test_a_look_that_moves_the_frontier_on_is_no_failure():
    """A short-range lidar at a door sees a few metres into the room: the frontier moves
    on (and a frontier near the same goal may keep the target's id); that look did its
    job."""
    c, a = on_its_way()
    c.on_status("r1", 1.0, RobotStatus(RobotState.REACHED, a.target))
    # what the robot saw at its goal: the corridor goes on 3 m, its end still open
    further = corridor_map(open_end=True).merge(rect(0.0, 0.0, 15.0, 2.0, (O, F, O, O))).map
    c.on_pose("r1", 1.0 + REACHED_GRACE_S, Pose(10.0, 1.0, 0.0, map_version=further.version))
    feed(c, "r1", further, 5.0)
    c.now += 2.0
    c.cycle()
    assert c.failures == {} and c.looks == {} and c.blacklist == []
    b = c.robots["r1"].assignment
    assert b is not None and b.goal[0] > a.goal[0] + 2.0  # sent on, further down


def test_repeated_failures_blacklist_a_target():
    c = coordinator(1)
    feed(c, "r1", corridor_map(open_end=True), 0.1)
    for k in range(Config().explore.blacklist_after_failures):
        c.now = 1.0 + 40.0 * k  # past the exclusion of a failed target
        c.cycle()
        a = c.robots["r1"].assignment
        assert a is not None and a.kind == AssignmentKind.EXPLORE
        c.on_status("r1", c.now, RobotStatus(RobotState.NAVIGATING, a.target))
        c.on_status("r1", c.now, RobotStatus(RobotState.UNREACHABLE, a.target))
    assert len(c.blacklist) > 0
    c.now += 40.0
    c.cycle()
    assert c.targets == {}  # the only frontier is blacklisted


def test_blacklisted_frontiers_get_one_more_round_before_the_mission_ends():
    """A frontier that failed twice (a planner that found no way through a door) ended
    TurtleBot3 office missions at 77-90 %: before the end, the blacklist is retried once
    per RETRY_GROWTH_M2 of new explored area; without new area, the mission ends."""
    c = coordinator(1)
    feed(c, "r1", corridor_map(open_end=True), 0.1)

    def fail_twice(t0: float) -> float:
        for k in range(Config().explore.blacklist_after_failures):
            c.now = t0 + 40.0 * k  # past the exclusion of a failed target
            if k > 0 or c.robots["r1"].assignment is None:
                c.cycle()
            a = c.robots["r1"].assignment
            assert a is not None and a.kind == AssignmentKind.EXPLORE
            c.on_status("r1", c.now, RobotStatus(RobotState.NAVIGATING, a.target))
            c.on_status("r1", c.now, RobotStatus(RobotState.UNREACHABLE, a.target))
        assert c.blacklist
        return c.now

    t = fail_twice(1.0)
    # no target left: after the end's confirmation the blacklist is retried, not ended
    for _ in range(END_CONFIRM_CYCLES + 2):
        t += Config().explore.end_confirm_s
        c.now = t
        c.cycle()
    assert c.state == MissionState.EXPLORING and c.blacklist == [] and c.failures == {}
    a = c.robots["r1"].assignment
    assert a is not None and a.kind == AssignmentKind.EXPLORE  # the frontier again
    # it fails twice more; the map has not grown since: now the mission ends
    t = fail_twice(t)
    for _ in range(END_CONFIRM_CYCLES + 2):
        t += Config().explore.end_confirm_s
        c.now = t
        c.cycle()
    assert c.state == MissionState.RETURNING and c.blacklist


def give_up_after_two_looks(c: Coordinator, a: Assignment, seen: GridPolyMap) -> float:
    """The robot reaches ``a`` twice and leaves its frontier open both times."""
    feed(c, "r1", seen, c.now)
    for k in range(Config().explore.blacklist_after_looks):
        if k > 0:
            c.now += EXCLUDE_S
            c.cycle()
            assert c.robots["r1"].assignment.target == a.target
        c.on_status("r1", c.now, RobotStatus(RobotState.NAVIGATING, a.target))
        c.on_status("r1", c.now, RobotStatus(RobotState.REACHED, a.target))
        c.on_pose("r1", c.now + REACHED_GRACE_S, Pose(10.0, 1.0, 0.0, map_version=seen.version))
        c.now += REACHED_GRACE_S + 1.0
        c.cycle()
    assert any(np.allclose(b, a.goal) for b in c.blacklist)
    return c.now


@pytest.mark.parametrize("changed_near", [False, True])
def test_a_frontier_given_up_after_looks_is_retried_only_once_its_cells_change(changed_near):
    """Two looks left a wall frontier open (a wall placed off by pose error): looking a
    third time at the same map would see the same. It gets one more round only if the
    merged cells near it changed since it was given up."""
    c, a = on_its_way()
    seen = corridor_map(open_end=True).merge(rect(0.0, 2.0, 2.0, 4.0, (O, O, O, O))).map
    t = give_up_after_two_looks(c, a, seen)
    later = seen.merge(rect(0.0, 4.0, 2.0, 6.0, (O, O, O, O))).map  # far from it: 4 m2
    if changed_near:  # a room beside the frontier's end (the frontier stays open)
        later = later.merge(rect(10.0, 2.0, 12.0, 4.0, (O, O, O, O))).map
    feed(c, "r1", later, t)
    for _ in range(END_CONFIRM_CYCLES + 2):
        t += Config().explore.end_confirm_s
        c.now = t
        c.cycle()
    if changed_near:
        assert c.state == MissionState.EXPLORING and c.blacklist == []
        b = c.robots["r1"].assignment
        assert b is not None and b.kind == AssignmentKind.EXPLORE and b.goal[0] > 9.0
    else:
        assert c.state == MissionState.RETURNING and len(c.blacklist) == 2


def test_a_delta_gap_is_refused_and_a_full_map_resyncs():
    c = coordinator(1)
    m = corridor_map(open_end=True)
    later = m.merge(rect(0.0, 2.0, 2.0, 4.0, (O, O, O, F))).map
    with pytest.raises(Exception, match="version"):
        c.on_robot_delta("r1", 0.1, later.delta_since(m.version))
    c.on_robot_map("r1", later)
    c.cycle()
    assert c.merged.explored_area() == pytest.approx(later.explored_area(), rel=1e-6)


def test_robot_merges_replay_on_its_copy_and_a_mismatch_resyncs_from_exact_cells():
    """A robot sends keyframes as merges: the coordinator replays them on its copy. A
    copy that is not bit-identical fails the digest, is left as it was, and is replaced
    by the robot's exact cells, on which the next merge replays."""
    opts = MergeOptions(0.05, 0.05, 0.01, 0.1, 0.08)

    def op_of(pmap, poly):
        res = pmap.merge(poly, opts)
        digest = cells_digest(res.map.cells[i] for i in res.changed)
        return res.map, MergeOp(2.0, pmap.version, res.map.version, poly, opts, digest)

    c = coordinator(1)
    robot, op = op_of(GridPolyMap(2.0), rect(-0.5, -0.5, 3.3, 0.7, (O, F, O, F)))
    assert c.on_robot_merge("r1", 0.1, decode_merge(encode_merge(op))) is not None
    robot, op = op_of(robot, rect(3.0, -0.5, 5.1, 0.7, (O, F, O, O)))
    delta = c.on_robot_merge("r1", 0.2, op)
    assert delta.version == robot.version  # journaled as the cells it changed
    assert {x.index for x in delta.cells} == {
        i for i, x in robot.cells.items() if x.version == robot.version
    }
    assert c.on_robot_merge("r1", 0.3, op) is None  # a duplicate changes nothing
    c.flush()
    assert c.merged.explored_area() == pytest.approx(robot.explored_area(), rel=1e-6)
    # r2's copy is at the robot's version but not bit-identical: another wall end, in a
    # cell the next merge changes (the digest covers the cells a merge changes)
    other, _ = op_of(GridPolyMap(2.0), rect(-0.5, -0.5, 3.3, 0.7, (O, F, O, F)))
    other, _ = op_of(other, rect(3.0, -0.5, 5.0, 0.7, (O, F, O, O)))
    assert other.version == robot.version
    c.on_robot_map("r2", other)
    later, op = op_of(robot, rect(4.2, 0.6, 4.9, 2.5, (O, O, O, F)))  # over the other end
    with pytest.raises(DeltaGapError, match="other cells"):
        c.on_robot_merge("r2", 0.4, op)
    assert c.robot("r2").map is other  # nothing applied
    # the coordinator fetches the robot's map, served as its exact cells: replays go on
    c.on_robot_map("r2", decode_any_map(encode_cells_map(later)))
    newest, op = op_of(later, rect(-0.4, 0.6, 0.4, 2.5, (O, O, F, O)))
    assert c.on_robot_merge("r2", 0.5, op) is not None
    copy = c.robot("r2").map
    assert copy.version == newest.version
    assert cells_digest(copy.cells.values()) == cells_digest(newest.cells.values())


def test_a_restored_coordinator_merges_what_it_had_applied_but_not_merged():
    """Killed between applying a robot's delta and merging it: the restored robot copy
    is merged at the next flush, so nothing the coordinator had received is lost."""
    m = corridor_map(open_end=True)
    c = coordinator(1)
    c.restore(GridPolyMap(2.0), {"r1": m})  # the merged map on disk lacks the corridor
    c.flush()
    assert c.merged.explored_area() == pytest.approx(m.explored_area(), rel=1e-6)


def test_cells_of_two_robots_in_the_same_cell_are_united():
    a = GridPolyMap(2.0).merge(rect(0.2, 0.2, 1.0, 1.8, (O, F, O, O))).map
    b = GridPolyMap(2.0).merge(rect(1.0, 0.2, 1.8, 1.8, (O, O, O, F))).map
    merged = GridPolyMap(2.0).merge_cells(list(a.cells.values()) + list(b.cells.values())).map
    assert merged.explored_area() == pytest.approx(0.8 * 1.6 * 2, rel=1e-6)


def test_a_wall_chord_of_one_robot_closes_on_another_robots_wall():
    # r1 saw the top wall at a grazing angle: a frontier chord 2 cm behind it; r2 saw
    # the wall head-on. The merged map has a wall there, and no frontier to visit.
    chord = GridPolyMap(2.0).merge(rect(0.1, 0.1, 3.9, 1.52, (O, O, F, O))).map
    wall = GridPolyMap(2.0).merge(rect(0.1, 0.1, 3.9, 1.50, (O, O, O, O))).map
    exact = GridPolyMap(2.0).merge_cells(list(chord.cells.values()) + list(wall.cells.values()))
    s, e, _ = exact.map.vectors([VectorType.FRONTIER])
    assert np.hypot(*(e - s).T).sum() == pytest.approx(3.8)  # the exact union keeps it
    c = coordinator(2)
    feed(c, "r1", chord, 0.1)
    feed(c, "r2", wall, 0.2)
    c.cycle()
    s, e, _ = c.merged.vectors([VectorType.FRONTIER])
    assert np.hypot(*(e - s).T).sum() == pytest.approx(0.0, abs=1e-6)
    assert c.merged.explored_area() == pytest.approx(3.8 * 1.42)  # nothing lost


def test_a_cycle_counts_all_the_work_done_in_the_coordinators_thread_since_the_last():
    """Applying a robot's cells and merging them happen between cycles: the next cycle's
    time includes them, and the stages add up to everything counted."""
    c = coordinator(1)
    feed(c, "r1", corridor_map(open_end=True), 0.1)
    c.now = 1.0
    c.cycle()
    assert {"deltas", "merge", "plan"} <= set(c.stage_ms)
    assert c.cycle_ms[-1] == pytest.approx(sum(c.stage_ms.values()), rel=1e-9)
    assert sum(c.stage_shares().values()) == pytest.approx(1.0)
    # a cycle with nothing received since: planning only
    before = dict(c.stage_ms)
    c.now = 2.0
    c.cycle()
    grew = {k for k in c.stage_ms if c.stage_ms[k] > before.get(k, 0.0)}
    assert grew <= {"plan", "merge"}
    assert c.cycle_ms[-1] == pytest.approx(
        sum(c.stage_ms[k] - before.get(k, 0.0) for k in c.stage_ms), rel=1e-9
    )


def test_a_coordinator_taking_over_keeps_each_robots_target_and_gives_none_twice():
    """The standby (this coordinator, its own target ids) adopts the active one's last
    assignments: the same frontier keeps the active's id, the robot is not re-sent
    elsewhere, and new targets get ids above every id heard (agents.leadership)."""
    c = coordinator(2)
    feed(c, "r1", corridor_map(open_end=True), 0.1)
    c.now = 1.0
    c.cycle()
    mine = c.robots["r2"].assignment  # what this one would have sent
    heard = Assignment(AssignmentKind.EXPLORE, 900, mine.goal, mine.frontier)
    c.adopt({"r2": heard}, max_target=950)
    assert c.robots["r2"].assignment == heard and c.robots["r1"].assignment is None
    assert 900 in c.targets and all(t == 900 or t > 950 for t in c.targets)
    c.now = 2.0
    out = c.cycle()
    assert out.assignments["r2"].target == 900  # sent again at once by the new leader
    assert "r1" not in out.assignments or out.assignments["r1"].target != 900
    assert c.new_target_id() > 950
