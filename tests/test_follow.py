"""The map follows the pose graph (polyswarm.follow): moved keyframes' cells are merged
again at the new poses, the rest stays bit for bit, and a receiver's copy follows."""

from __future__ import annotations

import dataclasses

import numpy as np
import shapely

from polyswarm.config import Config
from polyswarm.follow import follow
from polyswarm.polymap import GridPolyMap, MergeOptions, cells_digest
from polyswarm.slam import PolySlam
from polyswarm.submap import StoredKeyframe
from tests.conftest import rect


def _keyframe(pose, poly) -> StoredKeyframe:
    z = np.zeros((0, 2))
    return StoredKeyframe(np.array(pose, float), z, z, poly)


def test_a_moved_keyframe_takes_its_space_along_and_far_cells_stay_bit_for_bit():
    near = _keyframe((1.0, 1.0, 0.0), rect(-0.8, -0.8, 0.8, 0.8))  # a room around (1, 1)
    far = _keyframe((20.0, 1.0, 0.0), rect(-0.8, -0.8, 0.8, 0.8))  # another, far away
    kfs = [near, far]
    merged_at = np.array([kf.pose for kf in kfs])
    pmap = GridPolyMap(2.0)
    for kf in kfs:
        pmap = pmap.merge(kf.polygon_in_map()).map
    near.pose = np.array([1.5, 1.0, 0.0])  # the optimisation moved it 0.5 m
    out, at, info = follow(pmap, kfs, merged_at, MergeOptions())
    assert info["moved"] == 1 and info["cells"] > 0
    truth = shapely.box(0.7, 0.2, 2.3, 1.8)  # the room where its pose now puts it
    got = shapely.union_all([c.region for c in out.cells.values() if c.index[0] < 5])
    assert abs(got.area - truth.area) < 1e-6 and got.symmetric_difference(truth).area < 1e-6
    for ix, cell in pmap.cells.items():  # the far room's cells were not touched
        if ix[0] >= 5:
            assert out.cells[ix] is cell
    assert np.allclose(at[0], near.pose) and np.allclose(at[1], far.pose)
    # nothing moved any more: nothing to do
    again, _, info = follow(out, kfs, at, MergeOptions())
    assert again is out and info["moved"] == 0


def test_slam_with_the_map_following_the_graph_matches_the_rebuilt_map_and_a_copy_follows(
    shared_data,
):
    from polyswarm.io.carmen import read_carmen, real_odometry

    log = read_carmen(shared_data / "logs" / "aces-corrected.log.gz")
    odom = real_odometry(log)
    cfg = Config()
    slam_cfg = dataclasses.replace(cfg.slam, map_follows_graph=True)
    slam = PolySlam(slam_cfg, cfg.map.cell_size_m, initial_pose=log.reference[0])
    copy = GridPolyMap(cfg.map.cell_size_m)
    for k, s in enumerate(log.scans[:700]):  # the first loops of the building
        step = slam.process(s.scan, odom[k])
        if step.delta is not None:
            copy = copy.replay(step.op).map if step.op is not None else copy.apply_delta(step.delta)
    assert slam.corrections, "no loop closure moved the map"
    assert cells_digest(copy.cells.values()) == cells_digest(slam.map.cells.values())
    live, rebuilt = slam.map.explored_region(), slam.rebuild_map().explored_region()
    iou = shapely.intersection(live, rebuilt).area / shapely.union(live, rebuilt).area
    assert iou > 0.98
