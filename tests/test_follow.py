"""The map follows the pose graph (polyswarm.slam.follow): moved keyframes' cells are merged
again at the new poses, the rest stays bit for bit, and a receiver that holds the same
keyframes follows a correction sent as poses, bit for bit, or refuses it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import shapely

from polyswarm.config import Config
from polyswarm.errors import DecodeError, DeltaGapError, PolyswarmError
from polyswarm.polymap import GridPolyMap, MergeOptions, cells_digest, snap_polygon
from polyswarm.slam.follow import (
    Atlas,
    CorrectionOp,
    correct,
    frame_of,
    pose_of,
    quantize_pose,
    replay_correction,
)
from polyswarm.slam.polyslam import PolySlam
from protocols.mapcodec import decode_correction, encode_correction
from tests.conftest import rect

OPTIONS = MergeOptions(0.05, 0.05, 0.01, 0.1, 0.08).on_grid()


def _two_rooms() -> tuple[GridPolyMap, Atlas]:
    """A room around (1, 1) merged 0.5 m too far left, and another far away."""
    pmap, atlas = GridPolyMap(2.0), Atlas()
    for kid, room in enumerate([rect(0.2, 0.2, 1.8, 1.8), rect(19.2, 0.2, 20.8, 1.8)]):
        poly = snap_polygon(room, 100)
        pmap = pmap.merge(poly, OPTIONS).map
        atlas.add(kid, poly, OPTIONS)
    return pmap, atlas


def test_a_moved_keyframe_takes_its_space_along_and_far_cells_stay_bit_for_bit():
    pmap, atlas = _two_rooms()
    receiver_map, receiver_atlas = pmap, atlas.copy()
    poses = {k: pose_of(atlas.poses[k]) for k in (0, 1)}
    poses[0] = poses[0] + [0.5, 0.0, 0.0]  # the optimisation moved the first room 0.5 m
    out, op, info = correct(pmap, atlas, poses)
    assert op is not None and info["moved"] == 1 and info["cells"] > 0
    assert op.moves == ((0, (500, 0, 0)),) and op.version == pmap.version + 1
    truth = shapely.box(0.7, 0.2, 2.3, 1.8)  # the room where its pose now puts it
    got = shapely.union_all([c.region for c in out.cells.values() if c.index[0] < 5])
    assert got.symmetric_difference(truth).area < 1e-6
    for ix, cell in pmap.cells.items():  # the far room's cells were not touched
        if ix[0] >= 5:
            assert out.cells[ix] is cell
    # a receiver holding the same keyframes gets the same cells from the poses alone
    wire = encode_correction(op)
    assert len(wire) < 60
    got_map, got_atlas, changed = replay_correction(
        receiver_map, receiver_atlas, decode_correction(wire)
    )
    assert cells_digest(got_map.cells.values()) == cells_digest(out.cells.values())
    assert got_atlas.poses == atlas.poses  # the receiver's own atlas is untouched ...
    assert receiver_atlas.poses[0] == frame_of(receiver_atlas.polygons[0])  # ... until it applies
    assert changed and all(c.index[0] < 5 for c in changed)  # only the near room's cells
    # nothing moved any more: nothing to do
    again, op2, info = correct(out, atlas, poses)
    assert again is out and op2 is None and info["moved"] == 0


def test_a_turn_is_sent_as_a_step_from_where_the_receiver_holds_the_keyframe():
    pmap, atlas = _two_rooms()
    poses = {0: pose_of(atlas.poses[0]) + np.array([0.0, 0.0, 3.1]), 1: pose_of(atlas.poses[1])}
    _, op, _ = correct(pmap, atlas, poses)
    poses[0][2] += 0.2  # past pi: the step is 0.2 rad, not 0.2 - 2 pi
    _, op, _ = correct(pmap, atlas, poses)
    assert op is not None and op.moves[0][1] == (0, 0, 20_000)


@pytest.mark.parametrize("defect", ["unknown keyframe", "digest", "version", "no atlas"])
def test_a_correction_that_does_not_apply_is_refused_and_the_copy_is_unchanged(defect):
    pmap, atlas = _two_rooms()
    poses = {0: pose_of(atlas.poses[0]) + np.array([0.5, 0.0, 0.0]), 1: pose_of(atlas.poses[1])}
    _, op, _ = correct(pmap, atlas.copy(), poses)
    bad = {
        "unknown keyframe": dataclasses.replace(op, moves=((7, (500, 0, 0)),)),
        "digest": dataclasses.replace(op, digest=(op.digest + 1) % 2**32),
        "version": dataclasses.replace(op, base_version=op.base_version + 1),
        "no atlas": op,
    }[defect]
    receiver = Atlas() if defect == "no atlas" else atlas.copy()
    before = dict(receiver.poses)
    with pytest.raises(DeltaGapError):
        replay_correction(pmap, receiver, bad)
    assert receiver.poses == before


def test_a_pose_that_is_not_finite_is_refused():
    with pytest.raises(PolyswarmError):
        quantize_pose([1.0, float("nan"), 0.0])
    pmap, atlas = _two_rooms()
    with pytest.raises(PolyswarmError):
        correct(pmap, atlas, {0: np.array([np.inf, 0.0, 0.0])})


def test_the_correction_decoder_refuses_bad_bytes():
    op = CorrectionOp(2.0, 4, 5, ((3, (10, -20, 315)), (9, (-5, 6, 0))), 0xDEADBEEF)
    wire = encode_correction(op)
    assert decode_correction(wire) == op
    for bad in [wire[:-1], wire + b"\x00", b"\x81\xa1t\xa3map", b"", wire[:20]]:
        with pytest.raises(DecodeError):
            decode_correction(bad)
    with pytest.raises(PolyswarmError):  # ids must ascend
        encode_correction(dataclasses.replace(op, moves=op.moves[::-1]))


def test_a_long_correction_goes_compressed_and_bad_compressed_bytes_are_refused():
    import zlib

    import msgpack

    moves = tuple((k, (40 + k % 3, -25, 120)) for k in range(0, 400, 2))  # alike, as a loop's
    op = CorrectionOp(2.0, 10, 11, moves, 7)
    wire = encode_correction(op)
    assert "bz" in msgpack.unpackb(wire) and len(wire) < 2 * len(moves)
    assert decode_correction(wire) == op
    bomb = zlib.compress(b"\x00" * (300 * 1024 * 1024))  # 300 MB of zeros once inflated
    for bz in (b"not zlib", bomb, zlib.compress(b"\x01")[:-3], "text"):
        raw = msgpack.packb({"t": "polymap-correct", "v": 1, "bz": bz})
        with pytest.raises(DecodeError):
            decode_correction(raw)


def test_slam_following_the_graph_sends_corrections_a_receiver_and_the_coordinator_follow(
    shared_data,
):
    """PolySLAM on the first loops of the ACES log with its real odometry: everything
    goes through the wire format; the receiver's copy (and the coordinator's copy of the
    robot's map) equals the robot's map through the corrections; the merged map follows."""
    from agents.coordinator import Coordinator
    from polyswarm.benchmarks.bandwidth import Recording
    from polyswarm.io.carmen import read_carmen, real_odometry
    from protocols.chunks import MAP_KIND_OF
    from protocols.mapcodec import encode_updates

    log = read_carmen(shared_data / "logs" / "aces-corrected.log.gz")
    odom = real_odometry(log)
    cfg = Config()
    cfg = dataclasses.replace(cfg, slam=dataclasses.replace(cfg.slam, map_follows_graph=True))
    slam = PolySlam(cfg.slam, cfg.map.cell_size_m, initial_pose=log.reference[0])
    rec = Recording("aces")
    coord = Coordinator(cfg, {"r1": tuple(log.reference[0])})
    for k, s in enumerate(log.scans[:700]):  # the first loops of the building
        step = slam.process(s.scan, odom[k])
        if step.delta is None:
            continue
        rec.add("r1", float(s.stamp), s.scan, step.pose, step.delta, step.op, step.correction)
        for what, _, _, wire in encode_updates(step.delta, step.op, step.correction):
            coord.on_robot_update("r1", float(s.stamp), MAP_KIND_OF[what], wire)
    rec.maps["r1"] = slam.map
    assert len(rec.correction_ms) >= 3, "too few loop closures moved the map"
    assert rec.replay_failures == 0 and rec.copies_identical()
    robot_copy = coord.robot("r1").map
    assert cells_digest(robot_copy.cells.values()) == cells_digest(slam.map.cells.values())
    assert coord.corrections == len(rec.correction_ms)
    # the merged map (one robot) is that robot's map: ghosts it dropped left it too
    coord.flush()
    live, merged = slam.map.explored_region(), coord.merged.explored_region()
    assert shapely.symmetric_difference(live, merged).area < 0.01 * live.area
    # and the live map is the map rebuilt at the final poses
    rebuilt = slam.rebuild_map().explored_region()
    iou = shapely.intersection(live, rebuilt).area / shapely.union(live, rebuilt).area
    assert iou > 0.98
