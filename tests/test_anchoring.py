"""A robot that started where nobody measured moves into the shared frame when told."""

from __future__ import annotations

import numpy as np
import shapely

from polyswarm.config import Config, RobotEntry, known_starts
from polyswarm.mapmatch import transform_map
from polyswarm.polymap import cells_digest
from polyswarm.se2 import compose, relative
from polyswarm.slam import PolySlam


def test_unknown_starts_leave_the_first_robot_at_the_origin():
    both = (RobotEntry("a"), RobotEntry("b"))
    assert known_starts(both) == {"a": (0.0, 0.0, 0.0), "b": None}
    given = (RobotEntry("a"), RobotEntry("b", (1.0, 2.0, 0.5)))
    assert known_starts(given) == {"a": None, "b": (1.0, 2.0, 0.5)}


def test_an_anchored_slam_moves_its_map_as_one_correction_a_receiver_follows(shared_data):
    """PolySLAM on the ACES log from its own frame; after 300 scans it is told where
    that frame lies. The map moves as a whole (a correction of every keyframe), a copy
    kept from the wire follows it bit for bit, and SLAM goes on in the new frame."""
    from agents.coordinator import Coordinator
    from polyswarm.io.carmen import read_carmen, real_odometry
    from protocols.mapcodec import (
        CORRECTION_TYPE,
        MERGE_TYPE,
        decode_correction,
        decode_delta,
        decode_merge,
        encode_updates,
    )

    log = read_carmen(shared_data / "logs" / "aces-corrected.log.gz")
    odom = real_odometry(log)
    cfg = Config()
    slam = PolySlam(cfg.slam, cfg.map.cell_size_m)  # its own frame: its start
    coord = Coordinator(cfg, {"r1": (0.0, 0.0, 0.0)})
    frame = np.array([12.0, -7.5, 2.2])
    anchored_at = before = None
    for k, s in enumerate(log.scans[:360]):
        if k == 300:
            before, pose_before = slam.map, slam.pose.copy()
            slam.anchor(frame)
        step = slam.process(s.scan, odom[k])
        if step.anchored:
            anchored_at = k
            # the step's pose is the old one and the odometry's step since, moved
            pred = compose(frame, compose(pose_before, relative(odom[k - 1], odom[k])))
            assert np.hypot(*(step.pose[:2] - pred[:2])) < 0.2
        if step.delta is None:
            continue
        for what, _, _, wire in encode_updates(step.delta, step.op, step.correction):
            if what == MERGE_TYPE:
                coord.on_robot_merge("r1", float(s.stamp), decode_merge(wire))
            elif what == CORRECTION_TYPE:
                coord.on_robot_correction("r1", float(s.stamp), decode_correction(wire))
            else:
                coord.on_robot_delta("r1", float(s.stamp), decode_delta(wire))
        if k == anchored_at:  # right after the move: the map is the old one, moved
            moved = transform_map(before, frame).explored_region()
            now = slam.map.explored_region()
            assert shapely.symmetric_difference(moved, now).area < 0.05 * moved.area
    assert anchored_at == 300 and slam.anchors == 1
    copy = coord.robot("r1").map
    assert cells_digest(copy.cells.values()) == cells_digest(slam.map.cells.values())
    assert coord.gaps == 0
