"""Pose graph, keyframe store and wide loop search on geometry checkable by hand."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import shapely

from polyswarm.config import Config
from polyswarm.errors import PolyswarmError
from polyswarm.polymap import Ring, TypedPolygon
from polyswarm.se2 import compose, relative
from polyswarm.slam.loopsearch import correlative_search
from polyswarm.slam.polyslam import PolySlam
from polyswarm.slam.posegraph import PoseGraph
from polyswarm.slam.submap import KeyframeStore
from tests.conftest import O, rect, room, scan_at


def square_loop(heading_bias: float) -> tuple[PoseGraph, np.ndarray]:
    """A robot drives a 4 m x 4 m square in 16 steps of 1 m; its measured steps turn a
    little too much, so the chained poses do not close. Returns the graph (chained
    poses, sequential edges) and the true poses."""
    true = [np.zeros(3)]
    for k in range(16):
        step = (1.0, 0.0, math.pi / 2 if k % 4 == 3 else 0.0)
        true.append(compose(true[-1], step))
    g = PoseGraph()
    g.add_node(true[0])
    for k in range(16):
        z = relative(true[k], true[k + 1]) + np.array([0.0, 0.0, heading_bias])
        g.add_node(compose(g.poses[-1], z))
        g.add_edge(k, k + 1, z, sigma_m=0.05, sigma_rad=0.01)
    return g, np.array(true)


def test_loop_edge_closes_a_square():
    g, true = square_loop(heading_bias=0.01)
    before = np.hypot(*(g.poses[-1, :2] - true[-1, :2]))
    assert before > 0.3  # 16 steps of 0.01 rad: the chain misses its start by decimetres
    # the last pose is seen to be where the first one was (truth: the same place)
    g.add_edge(0, 16, relative(true[0], true[16]), sigma_m=0.01, sigma_rad=0.002, loop=True)
    poses = g.optimise()
    assert np.hypot(*(poses[-1, :2] - true[-1, :2])) < 0.05
    assert np.abs(np.hypot(*(poses[:, :2] - true[:, :2]).T)).max() < 0.1
    assert np.array_equal(poses[0], true[0])  # node 0 anchors the map frame
    assert g.loop_edges == 1


def test_weak_axis_lets_the_graph_move_along_a_corridor_only():
    g = PoseGraph()
    g.add_node((0, 0, 0))
    g.add_node((1.0, 0.0, 0.0))
    # a corridor along x: the measured step is trusted across it, not along it
    g.add_edge(0, 1, (1.0, 0.0, 0.0), 0.05, 0.01, weak_axis=(1.0, 0.0), weak_sigma_m=10.0)
    g.add_edge(0, 1, (1.5, 0.2, 0.0), 0.05, 0.01, loop=True)  # a loop edge says 1.5, 0.2
    p = g.optimise()[1]
    assert p[0] == pytest.approx(1.5, abs=0.01)  # along the corridor the loop wins
    assert p[1] == pytest.approx(0.1, abs=0.02)  # across it both count equally


def test_bad_edges_are_refused():
    g = PoseGraph()
    g.add_node((0, 0, 0))
    with pytest.raises(PolyswarmError):
        g.add_edge(0, 1, (1, 0, 0), 0.05, 0.01)
    g.add_node((1, 0, 0))
    with pytest.raises(PolyswarmError):
        g.add_edge(0, 1, (1, 0, 0), 0.0, 0.01)


def test_store_moves_vectors_with_their_keyframe():
    store = KeyframeStore(max_keyframes=5, radius_m=10.0, recent=1)
    pose = np.array([2.0, 1.0, math.pi / 2])
    store.add(pose, rect(0, 0, 4, 2))  # an obstacle rectangle seen from pose
    s, _ = store.reference(pose)
    assert sorted(map(tuple, np.round(s, 9))) == [(0, 0), (0, 2), (4, 0), (4, 2)]
    store.set_poses(np.array([[3.0, 1.0, math.pi / 2]]))  # corrected 1 m along x
    s, _ = store.reference(pose)
    assert sorted(map(tuple, np.round(s, 9))) == [(1, 0), (1, 2), (5, 0), (5, 2)]
    assert store.keyframes[0].polygon_in_map().to_shapely().bounds == pytest.approx((1, 0, 5, 2))


def test_store_picks_nearest_and_recent_keyframes():
    store = KeyframeStore(max_keyframes=2, radius_m=3.0, recent=1)
    for x in range(10):
        store.add((float(x), 0.0, 0.0), rect(x, 0, x + 0.5, 0.5, (O, O, O, O)))
    assert list(store.nearest((4.2, 0.0))) == [4, 5]
    assert list(store.nearest((4.2, 0.0), exclude_after=4)) == [3, 2]
    s, _ = store.reference((0.1, 0.0))
    assert len(s) == 3 * 4  # keyframes 0 and 1 (nearest) and 9 (the latest)


@pytest.mark.parametrize("offset", [(1.2, -0.6, 0.05), (-0.9, 1.1, -0.08)])
def test_wide_search_finds_an_offset_beyond_icp_reach(offset):
    s, e = room()
    true = np.array([3.0, 1.5, 0.3])
    pts = scan_at(true, s, e)
    found, score, ambiguous = correlative_search(pts, true + np.array(offset), s, e, 2.0)
    assert not ambiguous
    assert score > 0.8
    assert np.hypot(*(found - true)[:2]) < 0.1
    assert abs(found[2] - true[2]) < math.radians(1.5)


def test_wide_search_in_a_corridor_is_ambiguous():
    s = np.array([[-100.0, 0.0], [100.0, 2.0]])
    e = np.array([[100.0, 0.0], [-100.0, 2.0]])
    pts = scan_at(np.array([0.0, 1.0, 0.0]), s, e)
    _, _, ambiguous = correlative_search(pts, np.array([0.5, 1.0, 0.0]), s, e, 2.0)
    assert ambiguous


def test_slam_trajectory_follows_loop_corrections():
    """Drive round a room twice with odometry that turns too much: the second lap closes
    loops against the first, and trajectory() gives every scan a corrected pose."""
    from polyswarm.slam.scan import LaserScan

    s, e = room()
    cfg = Config()
    angles = np.linspace(-2.35, 2.35, 720)
    path = [
        np.array([1.0 + 4.0 * (0.5 - 0.5 * math.cos(t)), 2.0 - 1.0 * math.sin(t), 0.0])
        for t in np.linspace(0, 4 * math.pi, 160)
    ]
    slam = PolySlam(cfg.slam, cfg.map.cell_size_m, initial_pose=path[0], keep_trajectory=True)
    odom = path[0].copy()
    for k, p in enumerate(path):
        if k:
            z = relative(path[k - 1], p) + np.array([0.0, 0.0, 0.004])  # heading bias
            odom = compose(odom, z)
        from polyswarm.raycast import cast_rays

        r = cast_rays(p[:2], angles + p[2], s, e, 30.0)
        scan = LaserScan(r, float(angles[0]), float(angles[1] - angles[0]), 0.05, 30.0)
        slam.process(scan, odom)
    traj = slam.trajectory()
    assert len(traj) == len(path)
    err = np.hypot(*(traj[:, :2] - np.array(path)[:, :2]).T)
    assert err.max() < 0.1
    assert slam.loops_closed > 0
    assert slam.rejected_keyframes == 0
    rebuilt = slam.rebuild_map()  # 8 keyframes a pass
    assert rebuilt.explored_region().area == pytest.approx(
        slam.map.explored_region().area, rel=0.05
    )
    one_by_one = PolySlam(replace(cfg.slam, rebuild_batch=1), cfg.map.cell_size_m)
    one_by_one.store = slam.store
    apart = shapely.symmetric_difference(
        one_by_one.rebuild_map().explored_region(), rebuilt.explored_region()
    ).area
    assert apart < 0.01 * rebuilt.explored_region().area


def test_a_rebuild_batch_that_fails_is_merged_one_by_one_and_the_bad_keyframe_counted():
    cfg = Config()
    slam = PolySlam(cfg.slam, cfg.map.cell_size_m)
    for k in range(5):  # five 1 m squares along x, overlapping by half (map frame)
        slam.store.add((0.5 * k, 0.0, 0.0), rect(0.5 * k, 0.0, 0.5 * k + 1.0, 1.0))
    # a bow tie (self-intersecting) among them: its batch cannot be merged as a whole
    bow = TypedPolygon(Ring([(0, 0), (1, 1), (1, 0), (0, 1)], [O] * 4))
    slam.store.add((0.0, 2.0, 0.0), bow)
    pmap = slam.rebuild_map()
    assert slam.rejected_keyframes == 1
    assert pmap.explored_area() == pytest.approx(3.0)  # x from 0 to 3 m, 1 m wide


def test_the_wide_search_grows_with_the_distance_since_the_last_loop():
    lc = Config().slam.loop_closure
    assert lc.search_window(0.0) == lc.search_window_m  # 2 m just after a loop
    assert lc.search_window(100.0) == pytest.approx(3.0)  # 3 % of the distance driven
    assert lc.search_window(1000.0) == lc.max_search_window_m  # at most 5 m
    # a scan 3.5 m from where tracking put it (aces drifted 2-3 m over 160 m without a
    # loop): out of the 2 m window, found in the grown one
    s, e = room()
    true = np.array([3.0, 1.5, 0.3])
    pts = scan_at(true, s, e)
    tracked = true + np.array([2.5, -2.4, 0.03])
    found, _, ambiguous = correlative_search(pts, tracked, s, e, lc.search_window(200.0))
    assert not ambiguous
    assert np.hypot(*(found - true)[:2]) < 0.1
    found, _, _ = correlative_search(pts, tracked, s, e, lc.search_window(0.0))
    assert np.hypot(*(found - true)[:2]) > 1.0
