"""The robot's behaviour (agents/behaviour.py): its modes, with a real path follower on a
simulated unicycle and a wall the map does not know."""

from __future__ import annotations

import itertools
import math
from types import SimpleNamespace

import numpy as np

from agents.behaviour import MAX_RECOVERIES, RECOVER_BACK_M, Behaviour, Mode
from polyswarm.errors import OffMapError
from polyswarm.nav.control import ControlParams, PathFollower
from protocols.messages import Assignment, AssignmentKind, RobotState


class StraightLine:
    """Plans a straight path (the map shows nothing in the way)."""

    def __init__(self) -> None:
        self.looks = 0

    def plan(self, start, goal, partial):
        pts = np.array([start, goal], dtype=float)
        return SimpleNamespace(
            points=pts, length_m=float(np.hypot(*(goal - start))), reaches_goal=True
        )

    def yield_point(self, xy, other):
        return None

    def look_done(self):
        self.looks += 1


def drive(b: Behaviour, pose, seconds: float, wall_x: float | None = None, t0: float = 0.0):
    """Step the behaviour every 0.1 s on a unicycle; scan points of a wall at ``wall_x``
    (x = wall_x, |y| < 1) in the robot frame. Returns the poses and modes seen."""
    seen = []
    t = t0
    for _ in range(round(seconds / 0.1)):
        if wall_x is None:
            scan = np.zeros((0, 2))
        else:
            ys = np.linspace(-1.0, 1.0, 41)
            world = np.stack([np.full_like(ys, wall_x), ys], axis=1)
            c, s = math.cos(pose[2]), math.sin(pose[2])
            d = world - pose[:2]
            scan = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
        v, w = b.step(t, pose, scan, np.zeros(len(scan), dtype=bool), 0.0)
        b.follower.sent(v, w)
        pose = pose + 0.1 * np.array([v * math.cos(pose[2]), v * math.sin(pose[2]), w])
        seen.append((t, pose.copy(), b.mode))
        t += 0.1
    return pose, seen


def behaviour(fov_rad: float = 2 * math.pi) -> Behaviour:
    follower = PathFollower(ControlParams(radius_m=0.2, max_v_mps=0.5, period_s=0.1))
    return Behaviour("r2", follower, StraightLine(), 1.5, fov_rad)


def test_a_360_degree_lidar_needs_no_start_turn_and_a_270_degree_one_does():
    assert behaviour(2 * math.pi).mode == Mode.IDLE
    b = behaviour(math.radians(270))
    assert b.mode == Mode.START_TURN
    v, w = b.step(0.0, np.zeros(3), np.zeros((0, 2)), np.zeros(0, dtype=bool), 0.0)
    assert v == 0.0 and w > 0


def test_a_goal_with_a_frontier_is_looked_at_then_reached():
    b = behaviour()
    goal = Assignment(AssignmentKind.EXPLORE, 5, (3.0, 0.0), ((4.0, 1.0), (4.0, 3.0)))
    b.on_assignment(goal, 0.0, np.zeros(3))
    assert b.mode == Mode.NAVIGATE and b.state == RobotState.NAVIGATING
    pose, seen = drive(b, np.zeros(3), 20.0)
    modes = [m for _, _, m in seen]
    assert Mode.LOOK in modes and modes[-1] == Mode.REACHED
    assert b.planning.looks == 1 and b.state == RobotState.REACHED
    # it turned to face the frontier (to its left, up the y axis)
    assert (
        abs(math.remainder(math.atan2(2.0 - pose[1], 4.0 - pose[0]) - pose[2], 2 * math.pi)) < 0.35
    )


def test_a_robot_that_cannot_get_on_backs_off_along_its_trail_then_hands_its_target_back():
    b = behaviour()
    goal = Assignment(AssignmentKind.EXPLORE, 9, (5.0, 0.0), ((6.0, -1.0), (6.0, 1.0)))
    b.on_assignment(goal, 0.0, np.zeros(3))
    pose, seen = drive(b, np.zeros(3), 120.0, wall_x=2.5)  # a wall the map does not know
    modes = [m for _, _, m in seen]
    xs = np.array([p[0] for _, p, _ in seen])
    assert xs.max() < 2.5 - 0.2  # never into the wall
    first = modes.index(Mode.RECOVER)
    stopped_at = xs[first]
    after = [x for (_, _, m), x in zip(seen[first:], xs[first:], strict=True) if m == Mode.RECOVER]
    assert stopped_at - min(after) > 0.6 * RECOVER_BACK_M  # went back the way it came
    # recovered MAX_RECOVERIES times, then handed the target back: stuck, standing still
    starts = sum(1 for a, c in itertools.pairwise(modes) if c == Mode.RECOVER != a)
    assert starts == MAX_RECOVERIES
    assert modes[-1] == Mode.STUCK and b.state == RobotState.STUCK
    # a new target: it drives again
    b.on_assignment(Assignment(AssignmentKind.EXPLORE, 10, (0.0, 2.0), ()), 200.0, pose)
    assert b.mode == Mode.NAVIGATE
    # the same target given again later (after a stop): tried again, with its recoveries
    b.on_assignment(Assignment(AssignmentKind.STOP, -1, (0.0, 0.0), ()), 210.0, pose)
    b.on_assignment(goal, 220.0, pose)
    _, seen = drive(b, pose, 20.0, wall_x=2.5, t0=220.0)
    assert Mode.RECOVER in [m for _, _, m in seen]


class KnownUpToX1(StraightLine):
    """The map knows the space up to x = 1 m only: planning from beyond it fails."""

    def plan(self, start, goal, partial):
        if start[0] > 1.0:
            raise OffMapError(
                f"start ({start[0]:.2f}, {start[1]:.2f}) is not in explored free space"
            )
        return super().plan(start, goal, partial)


def test_a_robot_off_its_map_backs_into_known_space_instead_of_waiting():
    """Off the map, no path leads anywhere, for the robot or the coordinator: it goes
    back the way it came (into known space) rather than reporting the goal unreachable
    and standing there."""
    follower = PathFollower(ControlParams(radius_m=0.2, max_v_mps=0.5, period_s=0.1))
    b = Behaviour("r2", follower, KnownUpToX1(), 1.5, 2 * math.pi)
    b.on_assignment(Assignment(AssignmentKind.EXPLORE, 4, (5.0, 0.0), ()), 0.0, np.zeros(3))
    b._last_plan = math.inf  # no periodic replanning: the path holds until it fails
    pose, seen = drive(b, np.zeros(3), 4.0)  # on the path, past x = 1 m
    assert pose[0] > 1.2
    b._last_plan = -math.inf
    pose, seen = drive(b, pose, 30.0, t0=4.0)
    modes = [m for _, _, m in seen]
    assert Mode.RECOVER in modes and Mode.UNREACHABLE not in modes
    back = [p[0] for _, p, m in seen if m == Mode.RECOVER]
    assert min(back) < 1.0  # back in known space


def test_the_trail_moves_with_the_frame_when_the_robot_is_anchored():
    b = behaviour()
    for x in (0.0, 1.0, 2.0):
        b._record_trail(np.array([x, 0.0, 0.0]))
    b.move_frame((10.0, 5.0, math.pi / 2))  # the old frame's origin at (10, 5), turned left
    assert np.allclose(list(b._trail), [(10.0, 5.0), (10.0, 6.0), (10.0, 7.0)])


def test_nav2_giving_up_hands_the_target_back_until_the_next_one_and_success_looks_first():
    b = behaviour()
    goal = Assignment(AssignmentKind.EXPLORE, 5, (3.0, 0.0), ((4.0, 1.0), (4.0, 3.0)))
    b.on_assignment(goal, 0.0, np.zeros(3))
    b.on_nav_result(False, "Nav2 aborted")
    assert b.mode == Mode.UNREACHABLE and b.state == RobotState.UNREACHABLE
    _, seen = drive(b, np.zeros(3), 5.0)  # no replanning takes it back: Nav2 tried
    assert {m for _, _, m in seen} == {Mode.UNREACHABLE}
    b.on_assignment(Assignment(AssignmentKind.EXPLORE, 6, (0.0, 2.0), ()), 6.0, np.zeros(3))
    assert b.mode == Mode.NAVIGATE
    b.on_nav_result(True, "Nav2 succeeded")
    assert b.mode == Mode.REACHED  # no frontier to look at
    b.on_assignment(goal, 7.0, np.zeros(3))
    b.on_nav_result(True, "Nav2 succeeded")
    assert b.mode == Mode.LOOK  # then it turns to the frontier before reporting
    b.on_nav_result(False, "late word on an old goal")
    assert b.mode == Mode.LOOK
