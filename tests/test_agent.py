"""The robot agent's logic (agents/robot.py) without transport: scans in, status out."""

from __future__ import annotations

from agents.robot import STUCK_TIMEOUT_S, RobotAgent
from polyswarm.config import Config
from protocols.messages import Assignment, AssignmentKind, Odometry, RobotState
from tests.conftest import room_scan


def test_a_robot_that_cannot_move_tells_the_coordinator_it_is_stuck():
    # the wheels do nothing (odometry never changes): the status sent must say stuck,
    # or a coordinator waiting for the robot to get home waits for ever
    agent = RobotAgent("r1", Config(), (0.0, 0.0, 0.0))
    home = Assignment(AssignmentKind.HOME, 7, (3.0, 0.0))
    sent = []
    t = 0.0
    while t < 30.0:
        agent.on_odom(t, Odometry(0.0, 0.0, 0.0))
        out = agent.on_scan(t, room_scan(t))
        if t == 0.0:
            agent.on_assignment(home, t)
        if out.status is not None:
            sent.append((t, out.status.state, out.status.target))
        t = round(t + 0.1, 1)
    stuck = [s for s in sent if s[1] == RobotState.STUCK]
    assert stuck and stuck[0][2] == 7
    assert stuck[0][0] >= STUCK_TIMEOUT_S  # not before the timeout
