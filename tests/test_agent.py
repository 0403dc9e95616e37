"""The robot agent's logic (agents/robot.py) without transport: scans in, status out."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from agents.behaviour import MAX_RECOVERIES, STUCK_TIMEOUT_S
from agents.peers import PEER_FRESH_S
from agents.robot import RobotAgent
from polyswarm.config import Config
from polyswarm.polymap import VectorType
from protocols.messages import Assignment, AssignmentKind, Odometry, Pose, RobotState
from tests.conftest import room_scan


def test_a_robot_that_cannot_move_tells_the_coordinator_it_is_stuck():
    # the wheels do nothing (odometry never changes): after trying to get free, the status
    # sent must say stuck, or a coordinator waiting for the robot to get home waits for ever
    agent = RobotAgent("r1", Config(), (0.0, 0.0, 0.0))
    home = Assignment(AssignmentKind.HOME, 7, (3.0, 0.0))
    sent = []
    t = 0.0
    while t < 90.0:
        agent.on_odom(t, Odometry(0.0, 0.0, 0.0))
        out = agent.on_scan(t, room_scan(t))
        if t == 0.0:
            agent.on_assignment(home, t)
        if out.status is not None:
            sent.append((t, out.status.state, out.status.target))
        t = round(t + 0.1, 1)
    stuck = [s for s in sent if s[1] == RobotState.STUCK]
    assert stuck and stuck[0][2] == 7
    # not before it has tried: a timeout, then each recovery and its timeout
    assert stuck[0][0] >= (MAX_RECOVERIES + 1) * STUCK_TIMEOUT_S


def test_another_robot_in_the_scan_is_neither_mapped_nor_matched():
    # r2 stands 2 m ahead of r1 (a 0.2 m disc): the beams it stops are r2, not a wall
    scan = room_scan(0.0)
    r = np.asarray(scan.ranges, dtype=float).copy()
    on_peer = np.abs(scan.angles) < 0.09  # about 0.18 m either side at 2 m
    r[on_peer] = 1.8
    scan = replace(scan, ranges=r)
    agent = RobotAgent("r1", Config(), (0.0, 0.0, 0.0))
    agent.on_peer_pose("r2", 0.0, Pose(2.0, 0.0, 0.0))
    kept = np.asarray(agent._without_peers(scan, 0.0).ranges)
    assert np.isnan(kept[on_peer]).all()
    assert np.array_equal(kept[~on_peer], r[~on_peer])  # the walls are untouched
    # a pose older than PEER_FRESH_S says nothing about where r2 is now
    assert np.array_equal(agent._without_peers(scan, PEER_FRESH_S + 1.0).ranges, r)
    # through the whole step: the map has walls at 5 m and nothing where r2 stands
    agent.on_odom(0.0, Odometry(0.0, 0.0, 0.0))
    masked_before = agent.stats.peer_returns_masked
    agent.on_scan(0.0, scan)
    st, en, _ = agent.slam.map.vectors([VectorType.OBSTACLE])
    mid = 0.5 * (st + en)
    assert len(st) and np.hypot(*(mid - (2.0, 0.0)).T).min() > 1.0
    assert agent.stats.peer_returns_masked - masked_before == on_peer.sum()


def test_close_returns_off_the_map_are_remembered_for_planning_but_not_a_peers():
    """An obstacle 1 m ahead that the map does not hold goes into the planner's seen
    obstacles; another robot 1 m to the side does not (it moves)."""
    agent = RobotAgent("r1", Config(), (0.0, 0.0, 0.0))
    agent.on_odom(0.0, Odometry(0.0, 0.0, 0.0))
    agent.on_scan(0.0, room_scan(0.0))  # the first keyframe: walls of a room 5 m away
    agent.on_peer_pose("r2", 0.1, Pose(0.0, 1.0, 0.0))
    box = np.array([[1.0, y] for y in np.linspace(-0.2, 0.2, 5)])  # world frame, 0.1 m apart
    peer = np.array([[x, 1.0] for x in np.linspace(-0.15, 0.15, 7)])
    before = len(agent.seen)
    agent._remember_unmapped(0.1, np.vstack([box, peer]))
    seen = agent.seen.points(0.1)
    assert len(agent.seen) - before == len(box)
    assert np.hypot(*(seen[:, None, :] - peer[None]).transpose(2, 0, 1)).min() > 0.5


def _profiles_sent(cfg, anchor_at: int | None = None) -> list[tuple[int, bytes]]:
    """3 s of scans at 10 Hz by r1; r2's poses name an anchor from scan ``anchor_at``."""
    agent = RobotAgent("r1", cfg, (0.0, 0.0, 0.0))
    sent = []
    for k in range(30):
        t = 0.1 * k
        if k == anchor_at:  # r2's frame is found: its poses name the anchor
            agent.on_peer_pose("r2", t, Pose(3.0, 0.0, 0.0, frame=1))
        agent.on_odom(t, Odometry(0.0, 0.0, 0.0))
        out = agent.on_scan(t, room_scan(t))
        if out.pose is not None and out.pose.clear:
            sent.append((k, out.pose.clear))
    return sent


def test_poses_carry_the_scans_clear_profile_when_a_robot_started_in_a_frame_of_its_own():
    """Before r2's frame is found the profiles tell its frame's images apart; after, they
    audit it (``agents.anchoring``): at 1 Hz all along. A swarm whose starts were all
    given sends none."""
    from polyswarm.config import RobotEntry
    from polyswarm.frames.sighting import SECTORS

    cfg = replace(Config(), robots=(RobotEntry("r1", (0.0, 0.0, 0.0)), RobotEntry("r2")))
    sent = _profiles_sent(cfg, anchor_at=15)
    before = [c for k, c in sent if k < 15]
    after = [c for k, c in sent if k >= 15]
    assert len(before) == 2 and all(len(c) == SECTORS for c in before)  # at 1 Hz
    # the room's walls are 5-7.1 m away; behind, the 270-degree lidar sees nothing
    prof = np.frombuffer(before[0], np.uint8) * 0.2
    known = prof > 0
    assert known.sum() >= 0.7 * SECTORS
    assert np.all((prof[known] >= 4.8) & (prof[known] <= 7.1)), prof
    assert len(after) in (1, 2) and all(len(c) == SECTORS for c in after)
    told = replace(cfg, robots=(RobotEntry("r1", (0.0, 0.0, 0.0)), RobotEntry("r2", (3, 0, 0))))
    assert _profiles_sent(told) == []


def test_a_withdrawn_frame_is_a_frame_of_its_own_until_the_next_anchor(tmp_path):
    """An ``own`` anchor moves nothing; the robot stops planning on the merged map and
    around peers' poses (both in the shared frame), says the anchor's number in its
    poses, and a restart keeps it so. The next anchor moves it into the shared frame."""
    from agents import persist
    from polyswarm.config import RobotEntry
    from protocols.messages import Anchor

    cfg = replace(Config(), robots=(RobotEntry("r1"), RobotEntry("r2"), RobotEntry("r3")))
    agent = RobotAgent("r2", cfg, (0.0, 0.0, 0.0), frame_known=False)
    agent.frame = 1  # anchored once
    agent.on_odom(0.0, Odometry(0.0, 0.0, 0.0))
    agent.on_scan(0.0, room_scan(0.0))
    agent.on_merged_map(agent.slam.map)
    assert agent.in_shared_frame and agent.merged is not None
    pose, version = agent.pose.copy(), agent.slam.map.version
    agent.slam.graph.set_priors({0: np.zeros(3)}, 0.05, 0.01)  # the joint graph placed it
    agent.on_anchor(Anchor(2, 0.0, 0.0, 0.0, own=True))
    assert agent.frame == 2 and agent.own_frame and not agent.in_shared_frame
    assert agent.slam.graph.priors == {}  # given in the frame withdrawn
    assert agent.merged is None and np.array_equal(agent.pose, pose)
    agent.on_peer_pose("r1", 0.1, Pose(1.0, 0.0, 0.0, frame=0))
    assert agent.peers == {}
    agent.on_anchor(Anchor(2, 0.0, 0.0, 0.0, own=True))  # a resend: nothing
    poses = []
    for k in range(1, 8):  # its poses say so (peers do not plan around it)
        agent.on_odom(0.1 * k, Odometry(0.0, 0.0, 0.0))
        out = agent.on_scan(0.1 * k, room_scan(0.1 * k))
        poses += [out.pose] if out.pose is not None else []
    assert poses and all(p.frame == 2 and p.own for p in poses)
    assert agent.slam.map.version == version  # nothing moved
    persist.save_agent(tmp_path, "r2", agent.slam.map, agent.pose, frame=2, own_frame=True)
    again = RobotAgent("r2", cfg, (0.0, 0.0, 0.0), frame_known=False)
    again.resume(*persist.load_agent(tmp_path, "r2"))
    assert again.frame == 2 and again.own_frame and not again.in_shared_frame
    agent.on_anchor(Anchor(3, 1.0, 2.0, 0.5))
    agent.on_odom(0.8, Odometry(0.0, 0.0, 0.0))
    agent.on_scan(0.8, room_scan(0.8))
    assert agent.frame == 3 and not agent.own_frame and agent.in_shared_frame
    assert np.allclose(agent.pose, [1.0, 2.0, 0.5], atol=1e-6)
    agent.on_peer_pose("r3", 0.9, Pose(4.0, 0.0, 0.0, frame=2, own=True))
    assert "r3" not in agent.peers  # a peer whose frame was withdrawn: not planned around
    agent.on_peer_pose("r3", 0.9, Pose(4.0, 0.0, 0.0, frame=3))
    assert "r3" in agent.peers


def test_priors_in_another_frame_or_for_keyframes_not_held_are_ignored():
    """Joint pose graph priors apply only in the frame they were computed in, and only to
    keyframes the robot holds; those it takes move its map at the next keyframe."""
    from protocols.messages import Anchor, Priors

    agent = RobotAgent("r2", Config(), (0.0, 0.0, 0.0))
    for k in range(3):
        agent.on_odom(0.1 * k, Odometry(0.0, 0.0, 0.0))
        agent.on_scan(0.1 * k, room_scan(0.1 * k))
    held = sorted(agent.slam.atlas.poses)
    assert held
    frame = agent.slam.atlas.poses[held[0]]
    moved = (frame[0] + 100, frame[1], frame[2])  # 10 cm along x
    assert agent.on_priors(Priors(1, 0.05, 0.01, ((held[0], *moved),))) == 0  # frame 1: not ours
    assert agent.on_priors(Priors(0, 0.05, 0.01, ((10_000, *moved),))) == 0  # not held
    version = agent.slam.map.version
    assert agent.on_priors(Priors(0, 0.05, 0.01, ((held[0], *moved),))) == 1
    agent.on_odom(0.5, Odometry(0.0, 0.0, 0.0))
    out = agent.on_scan(0.5, room_scan(0.5))
    assert agent.slam.priors_applied == 1 and agent.slam.map.version > version
    assert out.pose is not None and out.pose.x > 0.05  # the robot's pose moved with its map
    other = RobotAgent("r3", Config(), (0.0, 0.0, 0.0))
    other.on_odom(0.0, Odometry(0.0, 0.0, 0.0))
    other.on_scan(0.0, room_scan(0.0))
    other.on_anchor(Anchor(1, 1.0, 0.0, 0.0))  # an anchor on its way: the frame changes
    assert other.on_priors(Priors(0, 0.05, 0.01, ((0, *moved),))) == 0


def test_a_team_anchor_moves_the_robot_into_a_frame_that_is_not_the_shared_one():
    """A ``team`` anchor moves the robot like any (its map and pose follow) but its
    coordinates stay out of the shared frame: no merged map, no peers, poses that say
    ``own``. The team's anchor in the shared frame then moves it there."""
    from polyswarm.config import RobotEntry
    from protocols.messages import Anchor

    cfg = replace(Config(), robots=(RobotEntry("r1"), RobotEntry("r2"), RobotEntry("r3")))
    agent = RobotAgent("r3", cfg, (0.0, 0.0, 0.0), frame_known=False)
    agent.on_odom(0.0, Odometry(0.0, 0.0, 0.0))
    agent.on_scan(0.0, room_scan(0.0))
    agent.on_anchor(Anchor(1, 2.0, -1.0, 0.5, team=True))
    poses = []
    for k in range(1, 8):
        agent.on_odom(0.1 * k, Odometry(0.0, 0.0, 0.0))
        out = agent.on_scan(0.1 * k, room_scan(0.1 * k))
        poses += [out.pose] if out.pose is not None else []
    assert agent.frame == 1 and agent.own_frame and not agent.in_shared_frame
    assert np.allclose(agent.pose, [2.0, -1.0, 0.5], atol=1e-6)  # moved into r2's frame
    assert np.allclose(agent.start_pose, [2.0, -1.0, 0.5], atol=1e-6)
    assert poses and all(p.frame == 1 and p.own for p in poses)
    agent.on_merged_map(agent.slam.map)
    agent.on_peer_pose("r1", 0.9, Pose(1.0, 0.0, 0.0, frame=0))
    assert agent.merged is None and agent.peers == {}
    agent.on_anchor(Anchor(2, 1.0, 1.0, 0.0))  # the team placed in the shared frame
    agent.on_odom(0.9, Odometry(0.0, 0.0, 0.0))
    agent.on_scan(0.9, room_scan(0.9))
    assert agent.frame == 2 and not agent.own_frame and agent.in_shared_frame
    assert np.allclose(agent.pose, [3.0, 0.0, 0.5], atol=1e-6)


def test_with_twist_output_the_agent_guards_what_its_controller_sends():
    """Its own controller drives a real base through cmd_vel: a forward command towards
    a return just beyond the body (a person who stepped in front) becomes a stop, a
    command over the limit is clamped; with the simulator's native output, neither."""
    from polyswarm.config import with_overrides

    person = np.array([[Config().nav.robot_radius_m + 0.01, 0.0]])
    twist = with_overrides(Config(), {"agent": {"output": "twist", "max_linear_mps": 0.3}})
    guarded = RobotAgent("r1", twist, (0.0, 0.0, 0.0))
    assert guarded._guarded((0.4, 0.2), person) == (0.0, 0.2)
    assert guarded._guarded((0.4, 0.2), np.zeros((0, 2))) == (0.3, 0.2)
    native = RobotAgent("r1", Config(), (0.0, 0.0, 0.0))
    assert native._guarded((0.4, 0.2), person) == (0.4, 0.2)
