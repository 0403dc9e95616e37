"""A robot that started where nobody measured moves into the shared frame when told."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from polyswarm.config import Config, RobotEntry, known_starts
from polyswarm.frames.mapmatch import transform_map
from polyswarm.polymap import GridPolyMap, cells_digest
from polyswarm.se2 import compose, inverse, relative, transform_points
from polyswarm.slam.polyslam import PolySlam


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
    from protocols.chunks import MAP_KIND_OF
    from protocols.mapcodec import encode_updates

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
            coord.on_robot_update("r1", float(s.stamp), MAP_KIND_OF[what], wire)
        if k == anchored_at:  # right after the move: the map is the old one, moved
            moved = transform_map(before, frame).explored_region()
            now = slam.map.explored_region()
            assert shapely.symmetric_difference(moved, now).area < 0.05 * moved.area
    assert anchored_at == 300 and slam.anchors == 1
    copy = coord.robot("r1").map
    assert cells_digest(copy.cells.values()) == cells_digest(slam.map.cells.values())
    assert coord.gaps == 0


def test_a_robot_is_merged_only_after_agreeing_matches_and_its_own_move():
    """In-process: robot r2's map (its own frame) goes to its solo coordinator, never to
    the merged map, until two matches agree, the anchor is sent, and a pose naming it
    arrives with the copy caught up."""
    import time

    from shapely.geometry import box

    from agents.anchoring import Anchoring
    from agents.coordinator import Coordinator
    from tests.conftest import seen_map

    truth = np.array([4.0, -3.0, 2.1])
    a = seen_map(box(-1, -8, 16, 9))  # r1's map, the shared frame
    b = seen_map(box(8, -8, 25, 9), truth)  # r2's, in its own frame
    cfg = Config()
    main = Coordinator(cfg, {"r1": (0.0, 0.0, 0.0)})
    main.on_robot_map("r1", a)
    main.flush()
    area = main.merged.explored_area()
    frames = Anchoring(cfg, ["r2"])
    solo = frames.owner("r2", main)
    assert solo is not main
    solo.on_robot_map("r2", b)
    _see_each_other(frames, truth)
    sent = []
    now, give_up = 0.0, time.monotonic() + 120.0
    while time.monotonic() < give_up:  # matches every MATCH_PERIOD_S, in a worker
        sent += frames.tick(main, now)
        if sent:
            break
        now += 1.0
        time.sleep(0.02)
    assert sent, "no anchor after the matches"
    rid, anchor = sent[0]
    assert rid == "r2" and anchor.frame == 1
    err_m = float(np.hypot(anchor.x - truth[0], anchor.y - truth[1]))
    assert err_m < 0.05 and abs(anchor.theta - truth[2]) < 0.01
    assert frames.waiting["r2"].matches >= 2  # one match is not trusted
    main.flush()
    assert main.merged.explored_area() == area  # nothing of r2 merged yet
    # the robot's pose names the anchor, but its moved map has not arrived: not yet
    assert not frames.on_pose("r2", 1, b.version + 1, main)
    moved = transform_map(b, truth)
    moved = GridPolyMap(moved.cell_size, moved.cells, b.version + 1)
    solo.on_robot_map("r2", moved)  # (the anchor's correction, as a whole map here)
    assert frames.on_pose("r2", 1, b.version + 1, main)
    assert frames.owner("r2", main) is main and "r2" not in frames.waiting
    main.flush()
    both = shapely.union(a.explored_region(), moved.explored_region()).area
    assert abs(main.merged.explored_area() - both) < 0.01 * both
    frames.close()


def _see_each_other(frames, truth, moments: int = 7) -> None:
    """r1 at the origin of the shared frame sees r2 drive 0.6 m a second from its own
    origin (which ``truth`` puts at (4 m, -3 m) in the shared frame) through a room of
    the building: 1.8 m along the shared x axis, then 1.8 m along -y."""
    from protocols.messages import Pose
    from tests.conftest import profile_with_a_robot_at

    for k in range(moments):
        there = truth[:2] + 0.6 * np.array([min(k, 3), -max(k - 3, 0)])
        mine = transform_points(inverse(truth), there[None])[0]
        clear = profile_with_a_robot_at(there)
        frames.sighted("r1", float(k), Pose(0.0, 0.0, 0.0, clear=clear))
        frames.sighted("r2", float(k), Pose(*mine, 0.0))


def _r2_waiting():
    """r1 mapped the west of the building (the shared frame); r2, whose start ``truth``
    puts at (4 m, -3 m), the east in its own frame, and waits for its frame: (truth, main
    coordinator, anchoring, r2's solo coordinator), both robots alive at their starts."""
    from shapely.geometry import box

    from agents.anchoring import Anchoring
    from agents.coordinator import Coordinator
    from protocols.messages import Pose
    from tests.conftest import seen_map

    truth = np.array([4.0, -3.0, 2.1])
    cfg = Config()
    main = Coordinator(cfg, {"r1": (0.0, 0.0, 0.0)})
    main.on_robot_map("r1", seen_map(box(-1, -8, 16, 9)))
    main.on_pose("r1", 0.0, Pose(0.0, 0.0, 0.0))
    main.on_alive("r1", True)
    main.flush()
    frames = Anchoring(cfg, ["r2"])
    solo = frames.owner("r2", main)
    solo.on_robot_map("r2", seen_map(box(8, -8, 25, 9), truth))
    solo.on_pose("r2", 0.0, Pose(0.0, 0.0, 0.0))
    solo.on_alive("r2", True)
    return truth, main, frames, solo


def _sighted_ticks(frames, main, t0: float, r1_clear: bytes, until) -> float:
    """Both robots at their starts, r1's scans with the clear profile ``r1_clear``: a pose
    each and ``frames.tick`` every half simulated second until ``until()``; now."""
    import time

    from protocols.messages import Pose

    now, give_up = t0, time.monotonic() + 120.0
    while not until() and time.monotonic() < give_up:
        frames.sighted("r1", now, Pose(0.0, 0.0, 0.0, clear=r1_clear))
        frames.sighted("r2", now, Pose(0.0, 0.0, 0.0))
        frames.tick(main, now)
        now += 0.5
        time.sleep(0.02)
    return now


def test_a_frame_the_robots_never_saw_each_other_at_is_sought_not_committed():
    """The maps agree (the same maps as above), but the robots never saw each other:
    nothing is committed, however long the matches agree; the waiting robot is drawn to
    where the frame they propose puts the other robot, in its own frame."""
    import time

    from agents.anchoring import MATCH_PERIOD_S
    from protocols.messages import Pose

    truth, main, frames, solo = _r2_waiting()
    for k in range(6):  # in each other's view, but r1's scans say nothing (no profile)
        frames.sighted("r1", float(k), Pose(0.0, 0.0, 0.0))
        frames.sighted("r2", float(k), Pose(0.0, 0.0, 0.0))
    w = frames.waiting["r2"]

    def tick_until(done) -> list:
        now, sent, give_up = 0.0, [], time.monotonic() + 120.0
        while not done(now) and time.monotonic() < give_up:
            sent += frames.tick(main, now)
            if w.matching is None:  # simulated time runs on between matches only
                now += MATCH_PERIOD_S
            time.sleep(0.05)
        return sent

    assert not tick_until(lambda now: w.matches >= 6)  # 30 s of agreeing matches
    assert w.matches >= 6 and len(w.frames.run) >= 2  # they ran, and agreed
    assert w.frames.pose is None and w.frames.candidate is not None
    assert solo.tour_first == set()  # never seen there: it explores its own frontiers
    r1_in_r2s_frame = transform_points(inverse(truth), np.zeros((1, 2)))[0]
    assert np.hypot(*(np.array(solo.rendezvous["r2"][:2]) - r1_in_r2s_frame)) < 0.1
    assert main.rendezvous == {}  # the swarm's robots go on exploring
    # the rendezvous changes the waiting robot's choices: the goal nearest it costs least
    goals = np.array([[0.0, 9.0], r1_in_r2s_frame])
    drawn = solo._drawn(np.zeros((1, 2)), goals, [solo.robots["r2"]])
    assert drawn[0, 1] < 0.1 < drawn[0, 0]
    frames.close()


def test_a_frame_that_puts_the_robot_where_another_saw_nothing_is_never_committed(caplog):
    """The same maps as above, but r1's lidar saw 10 m clear all around while r2 stood
    at its start, which the maps' frame puts 5 m from r1: r1 would have seen r2 there.
    The coordinator commits no frame; the match says why."""
    import time

    from shapely.geometry import box

    from agents.anchoring import Anchoring
    from agents.coordinator import Coordinator
    from polyswarm.frames.sighting import CLEAR_UNIT_M, SECTORS
    from protocols.messages import Pose
    from tests.conftest import seen_map

    truth = np.array([4.0, -3.0, 2.1])
    cfg = Config()
    main = Coordinator(cfg, {"r1": (0.0, 0.0, 0.0)})
    main.on_robot_map("r1", seen_map(box(-1, -8, 16, 9)))
    main.flush()
    frames = Anchoring(cfg, ["r2"])
    frames.owner("r2", main).on_robot_map("r2", seen_map(box(8, -8, 25, 9), truth))
    clear_10m = bytes([int(10 / CLEAR_UNIT_M)] * SECTORS)
    for k in range(20):
        frames.sighted("r1", 0.5 * k, Pose(0.0, 0.0, 0.0, clear=clear_10m))
        frames.sighted("r2", 0.5 * k, Pose(0.0, 0.0, 0.0))
    caplog.set_level("INFO", logger="agents.anchoring")
    now, sent, give_up = 0.0, [], time.monotonic() + 120.0
    while frames.waiting["r2"].matches < 3 and time.monotonic() < give_up:
        sent += frames.tick(main, now)
        now += 1.0
        time.sleep(0.05)
    w = frames.waiting["r2"]
    assert not sent and w.frames.pose is None
    assert w.matches >= 3, "the matches ran"
    assert "contradicted by sightings" in caplog.text
    frames.close()


def test_a_candidate_frame_the_sightings_come_to_contradict_is_forgotten(caplog):
    """The robots never saw each other: the agreeing matches' frame is a candidate and
    draws r2 to meet r1. Then r1's lidar sees 10 m clear all around while r2 stands
    where that frame puts it 5 m off: the next match forgets the candidate, and r2 is
    no longer drawn there (it was drawn for minutes when only a new proposal replaced
    a candidate)."""

    from polyswarm.frames.sighting import CLEAR_UNIT_M, SECTORS

    _, main, frames, solo = _r2_waiting()
    w = frames.waiting["r2"]
    caplog.set_level("INFO", logger="agents.anchoring")

    def run(t0: float, clear: bytes, until) -> float:
        return _sighted_ticks(frames, main, t0, clear, until)

    now = run(0.0, b"", lambda: w.frames.candidate is not None)  # no profiles: silence
    assert w.frames.candidate is not None and "r2" in solo.rendezvous
    clear_10m = bytes([int(10 / CLEAR_UNIT_M)] * SECTORS)
    run(now, clear_10m, lambda: w.frames.candidate is None)
    assert w.frames.candidate is None and w.frames.pose is None
    assert "of r2 contradicted by" in caplog.text and "sightings: forgotten" in caplog.text
    assert "saw clear where the frame put" in caplog.text  # the moments, logged
    frames.tick(main, now)
    assert solo.rendezvous == {}
    frames.close()


def test_a_robot_seen_where_the_candidate_frame_puts_it_tours_before_exploring():
    """r1's lidar has a return where the maps' frame puts r2 (5 m off): seen in one
    place, too few to commit; r2's solo coordinator sends it to tour standpoints in sight
    of r1 before its own frontiers (``tour_first``)."""

    from tests.conftest import profile_with_a_robot_at

    truth, main, frames, solo = _r2_waiting()
    w = frames.waiting["r2"]
    r2_seen = profile_with_a_robot_at(tuple(truth[:2]), clear_m=10.0)
    _sighted_ticks(frames, main, 0.0, r2_seen, lambda: bool(solo.tour_first))
    assert solo.tour_first == {"r2"} and "r2" in solo.rendezvous
    assert w.seen_at_candidate == 1 and w.frames.pose is None  # one place: not committed
    frames.close()


@pytest.mark.parametrize("out_of_frontiers", [True, False], ids=["swarm idle", "exploring"])
def test_an_idle_swarm_robot_tours_in_sight_of_a_waiting_one(out_of_frontiers):
    """Once the swarm has no frontier left, its robot nearest to where the candidate
    frame puts the waiting robot is drawn to that place (and tours standpoints there,
    ``Coordinator.rendezvous``): a robot standing still is seen in one place only. While
    the swarm explores it is not."""
    from tests.conftest import profile_with_a_robot_at

    truth, main, frames, solo = _r2_waiting()
    main.out_of_frontiers = out_of_frontiers
    r2_seen = profile_with_a_robot_at(tuple(truth[:2]), clear_m=10.0)
    _sighted_ticks(frames, main, 0.0, r2_seen, lambda: bool(solo.tour_first))
    assert solo.tour_first == {"r2"}
    if not out_of_frontiers:
        assert main.rendezvous == {}
    else:  # where r2 stands (its start, its pose (0, 0, 0) in its own frame)
        x, y, th = main.rendezvous["r1"]
        assert (
            math.dist((x, y), truth[:2]) < 0.2
            and abs(math.remainder(th - truth[2], math.tau)) < 0.05
        )
    frames.close()


def test_a_restarted_coordinator_leaves_a_robot_whose_frame_was_withdrawn_waiting():
    """After a restart every robot without a start pose waits; one whose poses name an
    anchor is taken as anchored, but not one whose poses say ``own`` (that anchor withdrew
    its frame, or put it in a team's frame, which the restarted coordinator does not
    know): it keeps waiting alone, and its poses count as sightings in its own frame."""
    from shapely.geometry import box

    from agents.anchoring import Anchoring
    from agents.coordinator import Coordinator
    from protocols.messages import Pose
    from tests.conftest import seen_map

    cfg = Config()
    main = Coordinator(cfg, {"r1": (0.0, 0.0, 0.0)})
    frames = Anchoring(cfg, ["r2", "r3"])
    for rid in ("r2", "r3"):
        frames.owner(rid, main).on_robot_map(rid, seen_map(box(8, -8, 25, 9)))
    assert not frames.on_pose("r2", 2, 0, main, own=True)
    assert "r2" in frames.waiting and frames.waiting["r2"].frame == 2
    frames.sighted("r2", 1.0, Pose(1.0, 2.0, 0.0, frame=2, own=True))
    assert len(frames.tracks["r2"]) == 1
    assert frames.on_pose("r3", 1, 0, main)  # anchored before the restart: handed over
    assert "r3" not in frames.waiting
    frames.close()


def test_a_match_proposes_the_image_of_the_frame_the_robots_saw_each_other_at():
    """A square room fits four ways; when the robots saw each other only where an image
    that did not score best puts them, the match proposes that image."""
    from agents.framematch import match_frame as _match
    from polyswarm.frames.estimate import MIN_SEEN
    from polyswarm.frames.mapmatch import fitting_rivals, frame_error, match_maps, verdict_at
    from polyswarm.polymap import Ring, TypedPolygon, VectorType

    xy = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 6.0], [0.0, 6.0]])
    room = TypedPolygon(Ring(xy, np.full(4, VectorType.OBSTACLE)), ())
    a = GridPolyMap.from_polygons([room], 2.0)
    b = transform_map(a, (1.0, 2.0, 0.3))
    best = match_maps(a, b, images=False)
    rivals = fitting_rivals(best)
    assert len(rivals) >= 2  # the other quarter turns
    truth = rivals[-1]

    def seen_at(pose) -> int:
        err_m, err_rad = frame_error(pose, truth)
        return MIN_SEEN if err_m < 0.3 and err_rad < math.radians(3) else 0

    assert seen_at(best.pose) == 0
    got = _match(a, b, None, seen_at)
    assert got.seen == MIN_SEEN and got.match.proposed
    err_m, err_rad = frame_error(got.match.pose, truth)
    assert err_m < 0.01 and err_rad < 1e-3
    with pytest.raises(ValueError):
        verdict_at(best, truth.copy())  # a pose that is not one of the match's own
    unseen = _match(a, b, None, lambda pose: 0)  # nobody seen anywhere: the best, as before
    assert frame_error(unseen.match.pose, best.pose)[0] < 0.01 and unseen.seen == 0


def test_two_waiting_robots_whose_maps_match_form_a_team_placed_as_one():
    """r2 and r3 wait; r1's map is too small to match with, theirs overlap, and r2 saw r3
    drive through three places where the truth puts it. r3 is sent a ``team`` anchor (its
    frame in r2's); once its poses name it and its copy caught up, r2's coordinator plans
    for both, each on frontiers of its own map. When the team's frame in the shared one
    is committed, both robots are anchored at it and handed over one by one."""
    import time

    from shapely.geometry import box

    from agents.anchoring import Anchoring
    from agents.coordinator import Coordinator
    from protocols.messages import Pose
    from tests.conftest import profile_with_a_robot_at, seen_map

    truth2, truth3 = np.array([6.0, 1.0, 0.4]), np.array([12.0, 1.0, 2.1])  # building frame
    rel = compose(inverse(truth2), truth3)  # r3's frame in r2's
    cfg = Config()
    main = Coordinator(cfg, {"r1": (0.0, 0.0, 0.0)})
    main.on_robot_map("r1", seen_map(box(-1, -8, 1, 2)))  # 2 m2: no match with it yet
    main.flush()
    frames = Anchoring(cfg, ["r2", "r3"])
    s2, s3 = frames.owner("r2", main), frames.owner("r3", main)
    b2, b3 = seen_map(box(3, -8, 16, 9), truth2), seen_map(box(8, -8, 21, 9), truth3)
    for rid, solo, b in (("r2", s2, b2), ("r3", s3, b3)):
        solo.on_robot_map(rid, b)
        solo.on_pose(rid, 0.0, Pose(0.0, 0.0, 0.0))
        solo.on_alive(rid, True)
    for k in range(7):  # r3 drives 1.8 m along x, then 1.8 m along -y, in r2's sight
        there = truth3[:2] + 0.6 * np.array([min(k, 3), -max(k - 3, 0)])
        seen = profile_with_a_robot_at(transform_points(inverse(truth2), there[None])[0])
        frames.sighted("r2", float(k), Pose(0.0, 0.0, 0.0, clear=seen))
        frames.sighted(
            "r3", float(k), Pose(*transform_points(inverse(truth3), there[None])[0], 0.0)
        )
    sent, now, give_up = [], 10.0, time.monotonic() + 120.0
    while not sent and time.monotonic() < give_up:
        sent = frames.tick(main, now)
        now += 1.0
        time.sleep(0.02)
    [(rid, anchor)] = sent
    assert rid == "r3" and anchor.team and not anchor.own and anchor.frame == 1
    got = np.array([anchor.x, anchor.y, anchor.theta])
    assert np.hypot(*(got[:2] - rel[:2])) < 0.05 and abs(got[2] - rel[2]) < 0.01
    assert frames.waiting["r3"].join == "r2" and frames.waiting["r2"].anchor is None
    # r3 moves into r2's frame: its copy follows, then a pose (its own frame, 1) hands it over
    moved = transform_map(b3, got)
    moved = GridPolyMap(moved.cell_size, moved.cells, b3.version + 1)
    assert not frames.on_pose("r3", 1, moved.version, main, own=True)  # copy behind
    s3.on_robot_map("r3", moved)
    assert not frames.on_pose("r3", 1, moved.version, main, own=True)  # not to the swarm
    assert frames.owner("r3", main) is s2 and frames.members("r2") == ["r2", "r3"]
    assert frames.coordinators() == [s2] and "r3" not in main.robots
    # its sightings moved into r2's frame, and the team's evidence holds both robots'
    first = frames.tracks["r3"].positions_at(np.array([0.0]))[0]
    assert np.hypot(*(first - rel[:2])) < 0.05
    _, _, (_, team_tracks) = frames._evidence("r2", {}, main.merged)
    assert len(team_tracks) == 2
    s2.flush()
    both = shapely.union(b2.explored_region(), moved.explored_region()).area
    assert abs(s2.merged.explored_area() - both) < 0.01 * both
    # the team's coordinator plans for both, each on a frontier of its own map (the
    # frontiers west of x = 3 m are r2's, those east of x = 21 m r3's)
    s2.on_pose("r3", now, Pose(*compose(got, np.zeros(3)), 0.0))
    out = s2.cycle()
    assert set(out.assignments) == {"r2", "r3"}
    for r, own in (("r2", b2), ("r3", moved)):
        assert own.is_free_many(np.array([out.assignments[r].goal]))[0]
    # the team's frame in the shared one committed: both robots anchored at it
    frames.waiting["r2"].frames.pose = truth2
    placed = dict(frames.tick(main, now))
    assert set(placed) == {"r2", "r3"} and placed["r3"].frame == 2 and placed["r2"].frame == 1
    assert not placed["r3"].team and placed["r2"].x == placed["r3"].x == truth2[0]
    there = transform_map(moved, truth2)
    s2.on_robot_map("r3", GridPolyMap(there.cell_size, there.cells, moved.version + 1))
    assert frames.on_pose("r3", 2, moved.version + 1, main)
    assert np.allclose(main.robots["r3"].start, truth3, atol=0.05)
    assert "r3" not in s2.robots and frames.owner("r2", main) is s2  # r2 still on its way
    frames.close()
