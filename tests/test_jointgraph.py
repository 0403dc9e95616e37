"""The joint pose graph on geometry checkable by hand: two robots that mapped the same
rooms, one of them placed 0.25 m and 1 degree off."""

import math

import numpy as np

from polyswarm.frames.jointgraph import JointGraph, KeyframeLedger, match_keyframe, moved_m
from polyswarm.polymap import Ring, TypedPolygon, VectorType
from polyswarm.se2 import compose, inverse, transform_points
from polyswarm.slam.follow import pose_of
from polyswarm.slam.posegraph import PoseGraph

OFF = (0.25, -0.1, math.radians(1.0))  # where r2 placed the rooms, in the map frame


def _truth(b: KeyframeLedger, kid: int) -> np.ndarray:
    """Where r2's keyframe frame belongs: moved as the rooms must be to lie on r1's."""
    return compose(inverse(OFF), pose_of(b.keyframes[kid].frame))


# a room of 10 x 6 m with a 2 x 2 m pillar: walls in both directions, no symmetry
ROOM = np.array([[0, 0], [10, 0], [10, 6], [0, 6]], dtype=float)
PILLAR = np.array([[6, 2], [6, 4], [8, 4], [8, 2]], dtype=float)  # clockwise: a hole


def _room(pose) -> TypedPolygon:
    ob = VectorType.OBSTACLE
    return TypedPolygon(
        Ring(transform_points(pose, ROOM), [ob] * 4),
        (Ring(transform_points(pose, PILLAR), [ob] * 4),),
    )


def _ledger(pose, n=7) -> KeyframeLedger:
    led = KeyframeLedger()
    for kid in range(n):
        led.merged(kid, _room(pose))
    return led


def test_a_keyframe_placed_off_is_matched_back_onto_the_other_robots_walls():
    a, b = _ledger((0, 0, 0)), _ledger(OFF)
    hit = match_keyframe(b.snapshot(), 3, a.snapshot())
    assert hit is not None
    a_kid, z, inliers = hit
    placed = compose(pose_of(a.keyframes[a_kid].frame), z)  # where the edge puts it
    truth = _truth(b, 3)
    assert np.hypot(*(placed[:2] - truth[:2])) < 0.02
    assert abs(placed[2] - truth[2]) < math.radians(0.1)
    assert inliers > 200  # most of the 40 m of wall


def test_a_start_most_of_a_metre_and_seven_degrees_off_is_still_matched():
    off = (0.8, -0.5, math.radians(7.0))  # walls 5 m out are more than a metre off
    a, b = _ledger((0, 0, 0)), _ledger(off)
    hit = match_keyframe(b.snapshot(), 3, a.snapshot())
    assert hit is not None
    a_kid, z, _ = hit
    placed = compose(pose_of(a.keyframes[a_kid].frame), z)
    truth = compose(inverse(off), pose_of(b.keyframes[3].frame))
    assert np.hypot(*(placed[:2] - truth[:2])) < 0.02
    assert abs(placed[2] - truth[2]) < math.radians(0.1)


def test_walls_that_do_not_agree_give_no_edge():
    a = _ledger((0, 0, 0))
    b = _ledger((2.5, 0, 0))  # beyond the fix a refinement may make: another place
    assert match_keyframe(b.snapshot(), 3, a.snapshot()) is None


def test_the_joint_solution_moves_the_robot_that_is_off_onto_the_reference():
    a, b = _ledger((0, 0, 0)), _ledger(OFF)
    ledgers = {"r1": a.snapshot(), "r2": b.snapshot()}
    joint = JointGraph()
    assert joint.find_edges(ledgers) == 3  # keyframes 0, 3 and 6 of r2
    assert joint.find_edges(ledgers) == 0  # edges are kept, not found again
    priors = joint.solve(ledgers, "r1")
    assert set(priors["r2"]) == {0, 3, 6}
    for kid, p in priors["r2"].items():
        truth = _truth(b, kid)
        assert np.hypot(*(p[:2] - truth[:2])) < 0.02
        assert abs(p[2] - truth[2]) < math.radians(0.1)
    assert moved_m(ledgers["r2"], priors["r2"]) > 0.25
    assert "r1" not in priors  # the reference holds the frame: it is not moved


def test_a_robot_whose_edges_disagree_or_are_few_is_left_where_it_is():
    """Half of r2's edges place its map 0.5 m from where the other half do (a map bent by
    drift, or wrong matches): no priors, rather than a compromise that fits neither; nor
    on two edges alone."""
    import dataclasses

    a, b = _ledger((0, 0, 0), n=10), _ledger(OFF, n=10)
    ledgers = {"r1": a.snapshot(), "r2": b.snapshot()}
    joint = JointGraph()
    joint.find_edges(ledgers)
    assert sorted(k for _, k in joint.edges) == [0, 3, 6, 9]
    assert set(joint.solve(ledgers, "r1")) == {"r2"}
    right = dict(joint.edges)
    for kid in (6, 9):
        e = joint.edges[("r2", kid)]
        joint.edges[("r2", kid)] = dataclasses.replace(e, z=compose(e.z, (0.5, 0.0, 0.0)))
    assert joint.solve(ledgers, "r1") == {}
    joint.edges = {k: right[k] for k in (("r2", 0), ("r2", 3))}
    assert joint.solve(ledgers, "r1") == {}


def test_a_correction_moves_the_ledgers_frames():
    led = _ledger((0, 0, 0), n=2)
    f = led.keyframes[1].frame
    led.corrected([(1, (100, -50, 2000))])
    assert led.keyframes[1].frame == (f[0] + 100, f[1] - 50, f[2] + 2000)
    assert led.keyframes[0].frame == _ledger((0, 0, 0), n=1).keyframes[0].frame


def test_priors_hold_the_frame_and_move_node_zero():
    g = PoseGraph()
    g.add_node((0, 0, 0))
    g.add_node((1, 0, 0))
    g.add_edge(0, 1, (1.0, 0.0, 0.0), 0.01, 0.01)
    g.set_priors({1: np.array([3.0, 1.0, 0.0])}, 0.05, 0.01)
    poses = g.optimise()
    assert np.allclose(poses[1], (3.0, 1.0, 0.0), atol=1e-3)
    assert np.allclose(poses[0], (2.0, 1.0, 0.0), atol=1e-3)
    g.move_all((0.0, 0.0, math.pi / 2))  # anchored into another frame: priors move along
    poses = g.optimise()
    assert np.allclose(poses[1], (-1.0, 3.0, math.pi / 2), atol=1e-3)


def test_two_simulated_robots_correct_the_one_placed_off_through_the_wire():
    """Two robots drive through the same rooms (pybullet, DIRECT); r2's SLAM starts 0.2 m
    and 1.5 degrees off its true pose, as a start measured badly. The coordinator's
    ledgers take both robots' merges from the wire, the joint graph sends r2 priors, r2's
    SLAM holds them and its map follows as a correction that the coordinator replays
    bit for bit: r2 ends near its true pose, and r1 stays where it was."""
    from agents.coordinator import Coordinator
    from polyswarm.config import Config
    from polyswarm.polymap import cells_digest
    from polyswarm.slam.polyslam import PolySlam
    from protocols.chunks import MAP_KIND_OF
    from protocols.mapcodec import encode_updates
    from protocols.messages import Priors, decode, encode
    from sim import Simulation, load_world

    cfg = Config()
    world = load_world("rooms")
    with Simulation(world, cfg.sim, 2) as sim:
        truth0 = [np.array(r.pose) for r in sim.robots]
        off = compose(truth0[1], (0.2, -0.1, math.radians(1.5)))
        slams = [
            PolySlam(cfg.slam, cfg.map.cell_size_m, truth0[0]),
            PolySlam(cfg.slam, cfg.map.cell_size_m, off),
        ]
        coord = Coordinator(cfg, {"r1": tuple(truth0[0]), "r2": tuple(off)})

        def drive(seconds: float) -> None:
            for e in sim.run(seconds):
                rid = f"r{e.robot + 1}"
                step = slams[e.robot].process(e.scan, e.odom)
                if step.delta is None:
                    continue
                for what, _, _, wire in encode_updates(step.delta, step.op, step.correction):
                    coord.on_robot_update(rid, sim.time, MAP_KIND_OF[what], wire)

        for i in range(2):
            sim.set_cmd(i, 0.0, 0.6)  # both turn on the spot: they see the same rooms
        drive(6.0)
        before = np.hypot(*(slams[1].pose[:2] - np.array(sim.robots[1].pose)[:2]))
        joint = JointGraph()
        ledgers = {rid: coord.robot(rid).ledger.snapshot() for rid in ("r1", "r2")}
        assert joint.find_edges(ledgers) > 0
        solved = joint.solve(ledgers, "r1")
        from polyswarm.slam.follow import quantize_pose

        q = tuple((k, *quantize_pose(p)) for k, p in sorted(solved["r2"].items()))
        _, msg = decode(encode(Priors(0, 0.05, 0.01, q), "coordinator", 0, 0.0), Priors)
        frames = {kid: pose_of((x, y, th)) for kid, x, y, th in msg.poses}
        assert slams[1].constrain(frames, msg.sigma_m, msg.sigma_rad) == len(frames)
        r1_before = slams[0].pose.copy()
        drive(1.0)
        after = np.hypot(*(slams[1].pose[:2] - np.array(sim.robots[1].pose)[:2]))
        r1_now = np.array(sim.robots[0].pose)
    assert slams[1].priors_applied == 1
    assert before > 0.15 and after < 0.05, (before, after)
    assert np.hypot(*(slams[0].pose[:2] - r1_now[:2])) < 0.05
    assert np.hypot(*(r1_before[:2] - r1_now[:2])) < 0.05  # r1 stood still
    for rid, slam in zip(("r1", "r2"), slams, strict=True):
        copy = coord.robot(rid).map
        assert cells_digest(copy.cells.values()) == cells_digest(slam.map.cells.values())


def test_the_coordinator_sends_priors_in_the_frame_each_robot_speaks_in():
    """``agents.joint``: the solve runs on a thread of its own; the robot whose keyframes
    it moves gets priors naming the anchor its poses name; the reference does not."""
    import time

    from agents.coordinator import Coordinator
    from agents.joint import JointCorrections
    from polyswarm.config import Config
    from polyswarm.polymap import GridPolyMap

    coord = Coordinator(Config(), {"r1": (0.0, 0.0, 0.0)})
    for rid, pose in (("r1", (0, 0, 0)), ("r2", OFF)):
        info = coord.robot(rid)
        info.ledger, info.map = _ledger(pose), GridPolyMap(2.0)
    coord.robot("r2").frame = 3  # anchored three times
    joint = JointCorrections()
    try:
        assert joint.tick(coord, 0.0, {"r2"}) == []  # started
        for _ in range(100):
            out = joint.tick(coord, 1.0, {"r2"})
            if out:
                break
            time.sleep(0.05)
    finally:
        joint.close()
    assert [rid for rid, _ in out] == ["r2"]
    priors = out[0][1]
    assert priors.frame == 3 and [p[0] for p in priors.poses] == [0, 3, 6]
    kid, x, y, th = priors.poses[1]
    truth = _truth(_ledger(OFF), kid)
    assert abs(x / 1000 - truth[0]) < 0.02 and abs(y / 1000 - truth[1]) < 0.02
    assert abs(th / 100_000 - truth[2]) < math.radians(0.1)


def test_priors_for_a_robot_whose_map_moved_during_the_solve_wait_for_the_next():
    """A loop of r2's own corrected its map while the solve ran: that solve's priors
    would pull its keyframes back, so they are dropped; the next solve sends fresh ones."""
    import time

    from agents.coordinator import Coordinator
    from agents.joint import JOINT_PERIOD_S, JointCorrections
    from polyswarm.config import Config
    from polyswarm.polymap import GridPolyMap

    coord = Coordinator(Config(), {"r1": (0.0, 0.0, 0.0)})
    for rid, pose in (("r1", (0, 0, 0)), ("r2", OFF)):
        info = coord.robot(rid)
        info.ledger, info.map = _ledger(pose), GridPolyMap(2.0)

    def wait(now_s: float) -> list:
        for _ in range(100):
            time.sleep(0.05)
            if joint._running is None:
                return []
            if joint._running.done():
                return joint.tick(coord, now_s, {"r2"})
        raise AssertionError("the solve did not finish")

    joint = JointCorrections()
    try:
        assert joint.tick(coord, 0.0, {"r2"}) == []  # started
        coord.robot("r2").ledger.corrections += 1  # r2 closed a loop meanwhile
        assert wait(1.0) == []
        assert joint.tick(coord, JOINT_PERIOD_S, {"r2"}) == []  # the next solve started
        out = wait(JOINT_PERIOD_S)
    finally:
        joint.close()
    assert [rid for rid, _ in out] == ["r2"]


def test_a_fix_the_walls_do_not_choose_over_no_fix_is_rivalled():
    """A corridor 1.1 m apart doors on both sides: a fix of one door spacing fits as well
    as none, so it is no edge; a fix that ICP from no fix finds again is."""
    from polyswarm.frames.jointgraph import _rivalled
    from polyswarm.frames.mapmatch import align_walls, wall_points, wall_tree

    starts, ends = [], []
    for k in range(10):  # wall pieces 0.8 m long with 0.3 m door gaps, both sides
        x = k * 1.1
        starts += [(x, 0.0), (x + 0.8, 2.0)]
        ends += [(x + 0.8, 0.0), (x, 2.0)]
    corridor = wall_points(np.array(starts), np.array(ends))
    local = wall_points(np.array(starts[4:12]), np.array(ends[4:12]))
    tree = wall_tree(corridor)
    assert _rivalled(corridor, local, tree, np.array([1.1, 0.0, 0.0]), len(local.walls))
    here = align_walls(corridor, local, np.zeros(3), tree)
    assert not _rivalled(corridor, local, tree, here, len(local.walls))
