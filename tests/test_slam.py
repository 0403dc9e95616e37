"""The PolySLAM pipeline, end to end on a small simulated world (real pybullet)."""

from __future__ import annotations

import numpy as np
import pytest

from polyswarm.config import Config, with_overrides
from polyswarm.errors import PlanningError
from polyswarm.evaluation.maps import map_iou
from polyswarm.nav.navgraph import NavGraph
from polyswarm.nav.planner import Planner
from polyswarm.polymap import GridPolyMap, cells_digest
from polyswarm.runners.slam import metrics, run_world
from polyswarm.slam.keyframe import KeyframeSelector
from polyswarm.slam.polyslam import PolySlam
from protocols.mapcodec import decode_merge, encode_merge
from sim import Simulation, load_world, spread_start_poses


def test_keyframe_selector_distance_and_angle():
    sel = KeyframeSelector(0.4, np.radians(20))
    assert sel.due(np.zeros(3))
    sel.mark(np.zeros(3))
    assert not sel.due(np.array([0.3, 0.0, 0.0]))
    assert sel.due(np.array([0.41, 0.0, 0.0]))
    assert not sel.due(np.array([0.0, 0.0, np.radians(19)]))
    assert sel.due(np.array([0.0, 0.0, np.radians(21)]))


def test_only_keyframes_carry_deltas():
    cfg = Config()
    w = load_world("rooms")
    with Simulation(w, cfg.sim, 1) as sim:
        slam = PolySlam(cfg.slam, cfg.map.cell_size_m, sim.robots[0].pose)
        sim.set_cmd(0, 0.3, 0.0)
        steps = [slam.process(e.scan, e.odom) for e in sim.run(3.0)]
    kf = [s for s in steps if s.keyframe]
    assert steps[0].keyframe and steps[0].delta is not None
    assert 2 <= len(kf) <= 4  # 0.9 m driven, a keyframe every 0.4 m
    assert all(s.delta is None for s in steps if not s.keyframe)
    versions = [s.delta.version for s in kf if s.delta]
    assert versions == sorted(versions)
    # every change is also a merge operation that a receiver replays to the same map
    copy = GridPolyMap(cfg.map.cell_size_m)
    for s in kf:
        if s.delta is not None:
            assert s.op is not None and s.op.version == s.delta.version
            copy = copy.replay(decode_merge(encode_merge(s.op))).map
    assert cells_digest(copy.cells.values()) == cells_digest(slam.map.cells.values())


@pytest.fixture(scope="module")
def rooms_run():
    return run_world("rooms", Config(), seed=3)


def test_simulated_run_is_accurate_and_maps_the_world(rooms_run):
    m = metrics(rooms_run)
    assert rooms_run.info["route_finished"]
    assert m["max_trans_error_m"] < 0.10
    assert m["max_rot_error_deg"] < 1.5
    assert m["ate_rmse_m"] < m["odometry_ate_rmse_m"]
    assert m["map_iou"] > 0.9
    assert m["wall_distance_mean_m"] < 0.05
    assert rooms_run.slam.rejected_keyframes == 0
    # the stages' times are reported and add up to the keyframe's
    stages = m["keyframe_stage_ms"]
    assert {"icp", "loop", "refine", "merge", "total"} <= set(stages)
    parts = sum(v["p50"] for k, v in stages.items() if k != "total")
    assert 0 < parts <= 1.5 * stages["total"]["p50"]


def test_map_explored_space_only_inside_the_world(rooms_run):
    w = rooms_run.world
    explored = rooms_run.map.explored_region()
    outside = explored.difference(w.free.buffer(0.1)).area
    assert outside < 0.01 * explored.area
    assert map_iou(explored, w.free) > 0.9


def test_a_robot_turning_at_the_maze_start_has_room_to_plan(shared_data):
    """The 1-robot maze start: corridors longer than the lidar's 30 m left beams with no
    return at the same bearings in every keyframe of the start turn. As points 0.2 m out
    they made thin unknown wedges meeting at the robot, which then had no graph node
    within reach ("no room for radius 0.3 m near the start") and never moved."""
    w = load_world("data:maze")
    base = Config()
    start = spread_start_poses(w, 1, base.sim.robot.radius_m)[0]
    radius = base.nav.robot_radius_m + base.nav.clearance_margin_m
    lengths = {}
    for free_m in (base.slam.frontier_range_m, base.slam.no_return_free_m):
        cfg = with_overrides(base, {"slam": {"no_return_free_m": free_m}})
        slam = PolySlam(cfg.slam, cfg.map.cell_size_m, initial_pose=start)
        with Simulation(w, cfg.sim, 1, start_poses=[start]) as sim:
            sim.set_cmd(0, 0.0, 0.6)  # a turn on the spot, as an agent's start turn
            for e in sim.run(6.0):
                slam.process(e.scan, e.odom)
        planner = Planner(slam.map, NavGraph.build(slam.map, radius))
        goal = slam.pose[:2] + np.array([1.2, 1.2])  # up the corridor beside the start
        try:
            lengths[free_m] = planner.plan(slam.pose[:2], goal).length_m
        except PlanningError as err:  # the old behaviour, recorded
            lengths[free_m] = str(err)
    # the scene still bites: no plan ("no room near the start", or with pockets between
    # frontiers filled by the merge, "no path")
    assert isinstance(lengths[base.slam.frontier_range_m], str)
    assert lengths[base.slam.no_return_free_m] == pytest.approx(np.hypot(1.2, 1.2), rel=0.05)


def test_a_resumed_slam_follows_the_odometry_of_the_robot_that_moved_while_it_was_down():
    """An agent killed and restarted resumes from its persisted pose; the robot base kept
    counting odometry (and moving) meanwhile. With the odometry reading saved beside the
    pose, the first keyframe after the restart starts where the robot really is."""
    cfg = Config()
    w = load_world("rooms")
    with Simulation(w, cfg.sim, 1) as sim:
        slam = PolySlam(cfg.slam, cfg.map.cell_size_m, sim.robots[0].pose)
        sim.set_cmd(0, 0.3, 0.0)
        for e in sim.run(2.0):
            slam.process(e.scan, e.odom)
        saved_map, saved_pose, saved_odom = slam.map, slam.pose.copy(), slam.odom.copy()
        # the agent is down; the robot drives on and turns
        sim.set_cmd(0, 0.4, 0.5)
        events = list(sim.run(3.0))
        truth = np.array(sim.robots[0].pose)
    assert np.hypot(*(truth[:2] - saved_pose[:2])) > 0.8  # a real gap to bridge
    e = events[-1]
    resumed = PolySlam(cfg.slam, cfg.map.cell_size_m)
    resumed.resume(saved_map, saved_pose, saved_odom)
    step = resumed.process(e.scan, e.odom)
    assert step.keyframe
    assert np.hypot(*(step.pose[:2] - truth[:2])) < 0.05
    assert abs(np.remainder(step.pose[2] - truth[2] + np.pi, 2 * np.pi) - np.pi) < 0.02


@pytest.mark.slow
def test_slam_on_csails_real_wheel_odometry_stays_on_the_reference(shared_data):
    """csail's real odometry is off by 15-30 degrees over some fast turns; ICP from such a
    prediction fell into a wrong minimum and the run ended 6.5 m off (ATE). A correlative
    search seeds ICP again after a poor fit."""
    from polyswarm.evaluation.trajectory import ate_rmse
    from polyswarm.runners.slam import OdometrySource, run_log

    run = run_log(
        shared_data / "logs" / "csail-corrected.log.gz", Config(), odometry=OdometrySource.LOG
    )
    assert run.info["odometry"] == "log"
    assert ate_rmse(run.odometry, run.reference) > 5.0  # the wheels alone: metres off
    assert ate_rmse(run.estimate, run.reference) < 0.2
    assert run.slam.reseeded > 0
