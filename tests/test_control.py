"""The local controller on situations checkable by hand."""

from __future__ import annotations

import numpy as np
import shapely

from polyswarm.nav.control import ControlParams, Follow, PathFollower, _segment_clearance


def follower(path) -> PathFollower:
    f = PathFollower(ControlParams(radius_m=0.2, max_v_mps=0.5, max_w_radps=1.5))
    f.set_path(np.array(path, dtype=float))
    return f


def drive(f: PathFollower, pose, points, moving: bool, steps: int):
    """Run the follower at 10 Hz on a base that reaches commanded velocities at the
    default accelerations (as the simulator's does), around fixed points (map frame).
    Yields the pose after each step."""
    pose = np.asarray(pose, dtype=float)
    vel = np.zeros(2)
    p = f.p
    dv = np.array([p.max_accel_mps2, p.max_angular_accel_radps2]) * 0.1
    for _ in range(steps):
        c, s = np.cos(pose[2]), np.sin(pose[2])
        d = points - pose[:2]
        local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
        cmd = f.command(pose, local, np.full(len(points), moving))
        f.sent(cmd.v_mps, cmd.w_radps)
        vel = vel + np.clip(np.array([cmd.v_mps, cmd.w_radps]) - vel, -dv, dv)
        th = pose[2] + 0.5 * vel[1] * 0.1
        pose = pose + 0.1 * np.array([vel[0] * np.cos(th), vel[0] * np.sin(th), vel[1]])
        yield pose


def test_free_straight_path_is_driven_forward():
    cmd = follower([[0, 0], [5, 0]]).command((0, 0, 0), np.zeros((0, 2)))
    assert cmd.state == Follow.DRIVING and cmd.v_mps > 0.3 and abs(cmd.w_radps) < 0.2


def test_pressed_against_a_wall_ahead_the_robot_backs_off():
    wall = np.array([[0.21, y] for y in np.linspace(-0.3, 0.3, 13)])  # 1 cm from its disc
    cmd = follower([[0, 0], [5, 0]]).command((0, 0, 0), wall)
    assert cmd.state == Follow.BLOCKED and cmd.v_mps < 0 and cmd.w_radps == 0


def test_blocked_with_a_wall_behind_too_it_waits():
    front = [[0.21, y] for y in np.linspace(-0.3, 0.3, 13)]
    back = [[-0.25, y] for y in np.linspace(-0.3, 0.3, 13)]
    cmd = follower([[0, 0], [5, 0]]).command((0, 0, 0), np.array(front + back))
    assert cmd.state == Follow.BLOCKED and cmd.v_mps == 0 and cmd.w_radps == 0


def test_an_unexplained_wall_inside_the_margin_only_forbids_getting_closer():
    # a wall 0.28 m to the left that the robot's map does not explain (kept 0.2 m farther
    # away than walls are): inside that margin from the start, every arc used to be
    # refused and the robot, facing its carrot, waited there for ever (seen in a maze run)
    wall = np.array([[x, 0.28] for x in np.linspace(-1.0, 1.0, 41)])
    poses = list(drive(follower([[0, 0], [5, 0]]), (0, 0, 0), wall, True, 40))
    assert poses[-1][0] > 0.3  # on along the wall, in 4 s...
    assert all(abs(0.28 - p[1]) >= 0.275 for p in poses)  # ... never closer to it
    # a carrot beyond the wall still cannot pull the robot into it
    cmd = follower([[0, 0], [0.5, 0.1], [5, 0.3]]).command(
        (0, 0, 0), wall, np.ones(len(wall), dtype=bool)
    )
    assert cmd.v_mps <= 0 or cmd.w_radps <= 0


def test_carrot_behind_a_door_jamb_is_replaced_by_one_in_sight():
    # path: 0.5 m east, then north through a gap; the jamb at (0.25, 0.3) hides the far
    # carrot (0.5, 0.5): heading for it would cut the corner into the jamb
    path = [[0, 0], [0.5, 0], [0.5, 3]]
    jamb = np.array([[x, 0.3] for x in np.linspace(-1.0, 0.25, 26)])
    cmd = follower(path).command((0, 0, 0), jamb)
    assert cmd.state == Follow.DRIVING and abs(cmd.w_radps) < 0.5  # on along the first leg
    assert _segment_clearance(np.array([0.5, 0.5]), jamb) < 0.23  # the far carrot: blocked


def test_segment_clearance_by_hand():
    pts = np.array([[1.0, 1.0], [3.0, 0.0], [-1.0, 0.0]])
    assert _segment_clearance(np.array([2.0, 0.0]), pts) == 1.0
    assert _segment_clearance(np.array([2.0, 0.0]), np.zeros((0, 2))) == float("inf")


def test_points_inside_the_margin_never_draw_the_robot_into_contact():
    # unexplained points 1-2 cm outside the robot's disc, around the path: each step may
    # get a few millimetres closer to a point than the step before, and that slack must
    # not add up to contact over many steps
    rng = np.random.default_rng(3)
    for trial in range(20):
        a = rng.uniform(-2.0, 2.0, 2)
        r = rng.uniform(0.212, 0.23, 2)  # two points just outside the disc...
        near = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
        pts = np.vstack([near, rng.uniform([0.5, -0.6], [3.0, 0.6], size=(3, 2))])
        pts = pts[np.hypot(pts[:, 0], pts[:, 1]) > 0.212]  # ... and a few farther on
        f = follower([[0, 0], [3, rng.uniform(-0.5, 0.5)]])
        pose = np.zeros(3)
        for _ in range(80):  # 8 s at 10 Hz, unicycle kinematics
            c, s = np.cos(pose[2]), np.sin(pose[2])
            d = pts - pose[:2]
            local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
            cmd = f.command(pose, local, np.ones(len(pts), dtype=bool))
            pose = pose + 0.1 * np.array([cmd.v_mps * c, cmd.v_mps * s, cmd.w_radps])
            assert np.hypot(*(pts - pose[:2]).T).min() >= 0.2, trial  # radius 0.2 m


def test_blocked_in_front_of_a_corner_with_the_carrot_ahead_it_turns_away_and_passes():
    # seen in a maze run: a robot beside the end of a wall, 0.27 m from its corner, the
    # wall not yet in its map (kept 0.2 m farther away than walls), its carrot straight
    # ahead past the corner. Every forward arc got closer to the corner and was refused,
    # and the carrot was too far ahead of the heading to turn to it: the robot stood
    # there for 300 simulated seconds. Map frame, metres: the wall's end, then its face
    # running north
    stub = shapely.Polygon(
        [(3.6, -41.5), (3.6, -44.0), (3.8, -44.0), (3.8, -44.2), (4.0, -44.2), (4.0, -41.5)]
    )
    ring = stub.exterior
    pts = np.array(
        [ring.interpolate(t).coords[0] for t in np.arange(0.0, ring.length, 0.01)], dtype=float
    )
    f = follower([[3.537, -44.272], [3.3, -43.5], [3.2, -40.0]])
    for pose in drive(f, (3.537, -44.272, 2.057), pts, True, 150):  # heading 118 degrees
        assert shapely.distance(stub, shapely.Point(pose[:2])) >= 0.2  # radius 0.2 m
    assert pose[1] > -43.2  # past the wall's end, on its way north (creeping: the wall
    # is not in its map)
