"""Sightings: a frame that puts one robot where another's lidar saw nothing is refused."""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import box

from polyswarm.frames.mapmatch import PEAKS, frame_error, match_maps, transform_map
from polyswarm.frames.mapsearch import search as coarse_to_fine
from polyswarm.frames.sighting import (
    CLEAR_UNIT_M,
    MIN_CONTRADICTIONS,
    SECTORS,
    WALL_CLEAR_M,
    Room,
    Sighting,
    Track,
    clear_profile,
    contradicted_where,
    contradictions,
    distinct_places,
    mutual_seen,
    no_wall_test,
    seen,
    seen_where,
    unseen,
)
from polyswarm.polymap import GridPolyMap
from polyswarm.se2 import compose, inverse, transform_points
from tests.conftest import CELL_M, profile_with_a_robot_at, typed_regions

ROBOT_RADIUS_M = 0.2


def test_a_clear_profile_holds_each_sectors_nearest_return():
    ahead, left = np.array([[5.0, 0.05], [7.0, -0.05]]), np.array([[0.0, 2.3]])
    prof = np.frombuffer(clear_profile(np.vstack([ahead, left])), np.uint8)
    k_ahead = SECTORS // 2  # sector k spans bearings from -pi + k * 2pi / SECTORS
    k_left = int((math.pi / 2 + math.pi) / (2 * math.pi) * SECTORS)
    # 0.6 deg left of ahead, 0.4 deg right of it: two sectors, each its own return
    assert prof[k_ahead] == math.floor(5.0 / CLEAR_UNIT_M)
    assert prof[k_ahead - 1] == math.floor(7.0 / CLEAR_UNIT_M)
    assert prof[k_left] == math.floor(2.3 / CLEAR_UNIT_M)
    assert np.count_nonzero(prof) == 3  # no return, nothing known
    # a dropout beam ahead: that sector and its neighbours say nothing
    blind = np.frombuffer(clear_profile(np.vstack([ahead, left]), np.array([0.0])), np.uint8)
    assert blind[k_ahead - 1 : k_ahead + 2].sum() == 0 and blind[k_left] == prof[k_left]


def test_positions_are_interpolated_only_between_close_poses():
    t = Track()
    for s, x in ((0.0, 0.0), (1.0, 1.0), (5.0, 2.0)):
        t.add(Sighting(s, (x, 0.0, 0.0)))
    got = t.positions_at(np.array([0.5, 3.0, 6.0]))
    assert np.allclose(got[0], (0.5, 0.0))
    assert np.isnan(got[1:]).all()  # 4 s between poses; after the last one


def test_a_tracks_paths_break_where_poses_are_far_apart_in_time():
    t = Track()
    assert t.paths() == []
    for s, x in ((0.0, 0.0), (1.0, 1.0), (5.0, 2.0), (5.5, 2.5)):
        t.add(Sighting(s, (x, 0.0, 0.0)))
    got = t.paths()
    assert [p[:, 0].tolist() for p in got] == [[0.0, 1.0], [2.0, 2.5]]  # 4 s gap: no line


def test_a_robot_predicted_inside_what_another_saw_clear_is_a_contradiction():
    viewer, other = Track(), Track()
    clear_10m = bytes([int(10 / CLEAR_UNIT_M)] * SECTORS)
    for s in np.arange(0.0, 3.0, 0.5):
        viewer.add(Sighting(s, (0.0, 0.0, 0.0), clear_10m))
        other.add(Sighting(s, (0.0, 0.0, 0.0)))  # at its own frame's origin all along
    assert unseen(viewer, other, (5.0, 0.0, 0.0)) == 6  # 5 m out where 10 m were clear
    assert unseen(viewer, other, (9.5, 0.0, 0.0)) == 0  # at the edge: it may be the return
    assert unseen(viewer, other, (-20.0, 3.0, 1.0)) == 0  # beyond what was seen
    assert unseen(other, viewer, (5.0, 0.0, 0.0)) == 0  # the other sent no profile
    # the same moments as evidence, in the viewer's frame: the viewer (0, not the
    # other: 1) at its origin, the other put 5 m ahead, from 0 s on, once a half second
    rows = contradicted_where(viewer, other, (5.0, 0.0, 0.0))
    assert rows.shape == (6, 6) and np.allclose(rows[:, 0], np.arange(0.0, 3.0, 0.5))
    assert np.allclose(rows[:, 1:], [0.0, 0.0, 0.0, 5.0, 0.0])
    # seen from the other robot's side (it is A now): the viewer is B, its moments
    # placed in A's frame by the frame (B 5 m behind A: the viewer at (-5, 0), A at 0)
    back = contradicted_where(other, viewer, (-5.0, 0.0, 0.0))
    assert np.allclose(back[:, 1:], [1.0, -5.0, 0.0, 0.0, 0.0])


# -- a ring corridor: the maps fit four ways; the robots' sightings tell them apart --------

RING = shapely.difference(box(0, 0, 20, 20), box(2, 2, 18, 18))


def _corridor_map() -> GridPolyMap:
    """A 2 m wide corridor, 30 m long, along x from (0, 0); its walls at y = +-1 m."""
    hall = box(-0.5, -1.0, 30.0, 1.0)
    return GridPolyMap.from_polygons(typed_regions(hall, hall.boundary), CELL_M)


def test_a_room_is_the_explored_space_a_robots_centre_fits_in():
    room = Room(_corridor_map())
    got = room.allows(np.array([[10.0, 0.0], [10.0, 0.75], [10.0, 0.97], [10.0, 1.5], [40, 0]]))
    assert got.tolist() == [True, True, False, False, False]  # 3 cm from the wall: no
    assert not Room(GridPolyMap(CELL_M)).allows(np.zeros((1, 2))).any()  # an empty map


def test_along_a_corridor_only_where_a_robot_can_stand_is_looked_at():
    """Looking down a corridor clear for 25 m, a robot predicted 0.6 m from its wall 10 m
    out: the disc around the prediction reaches the wall (its sectors' returns are the
    wall's), so without the map nothing is concluded; within the corridor every place
    the robot could stand was in clear view: contradicted."""
    viewer, other = Track(), Track()
    profile = np.zeros(SECTORS, dtype=np.uint8)
    for k in range(SECTORS):  # the corridor's walls as the viewer at (0, 0, 0) sees them
        b = (k + 0.5) * 2 * math.pi / SECTORS - math.pi
        r = 25.0 if abs(math.sin(b)) < 1e-9 else min(25.0, 1.0 / abs(math.sin(b)))
        profile[k] = min(255, int(r / CLEAR_UNIT_M)) if math.cos(b) > 0 else 2
    for s in np.arange(0.0, 3.0, 0.5):
        viewer.add(Sighting(s, (0.0, 0.0, 0.0), bytes(profile)))
        other.add(Sighting(s, (0.0, 0.0, 0.0)))
    near_wall = (10.0, 0.4, 0.0)
    assert unseen(viewer, other, near_wall) == 0
    assert unseen(viewer, other, near_wall, Room(_corridor_map())) == 6
    # a return where the robot is predicted (it was seen): not contradicted
    profile[SECTORS // 2] = int(9.8 / CLEAR_UNIT_M)
    profile[SECTORS // 2 + 1] = int(9.8 / CLEAR_UNIT_M)
    seen_track = Track()
    for s in np.arange(0.0, 3.0, 0.5):
        seen_track.add(Sighting(s, (0.0, 0.0, 0.0), bytes(profile)))
    centre = (10.0, 0.1, 0.0)
    assert unseen(seen_track, other, centre, Room(_corridor_map())) == 0
    # and that return, clear of the walls with the corridor free behind it, is a sighting
    no_wall = no_wall_test(_corridor_map())
    assert seen(seen_track, other, centre, no_wall) == 6
    assert seen(viewer, other, centre, no_wall) == 0  # the returns there are the walls'
    assert WALL_CLEAR_M < 1.0  # the corridor's middle is farther than that from its walls


def test_a_robot_whose_body_the_viewer_mapped_is_not_contradicted_where_it_stood():
    """The viewer at (0, 0) watched the other robot stand 10 m down the corridor: a return
    9.8 m out in one sector, and its map holds the body (a wall) with its shadow behind,
    the sector's width. In the viewer's map alone, the places left to stand in the disc
    are beside the shadow or in front of the body, all in clear view: the truth was
    contradicted. The other robot's own map (no body in it) lets it stand at its
    footprint: not contradicted. A frame 5 m nearer, where the viewer saw the corridor
    clear, still is."""
    step = 2 * math.pi / SECTORS
    body = SECTORS // 2  # the sector of bearings 0 to 2.8 degrees
    profile = np.zeros(SECTORS, dtype=np.uint8)
    for k in range(SECTORS):  # the corridor's walls, and the body 9.8 m out
        b = (k + 0.5) * step - math.pi
        r = 25.0 if abs(math.sin(b)) < 1e-9 else min(25.0, 1.0 / abs(math.sin(b)))
        profile[k] = min(255, int(r / CLEAR_UNIT_M)) if math.cos(b) > 0 else 2
    profile[body] = int(9.8 / CLEAR_UNIT_M)
    viewer, other = Track(), Track()
    for s in np.arange(0.0, 3.0, 0.5):
        viewer.add(Sighting(s, (0.0, 0.0, 0.0), bytes(profile)))
        other.add(Sighting(s, (0.0, 0.0, 0.0)))
    hall = box(-0.5, -1.0, 30.0, 1.0)
    shadow = shapely.Polygon(
        [(9.8, 0.0), (30.0, 0.0), (30.0, 30.0 * math.tan(step)), (9.8, 9.8 * math.tan(step))]
    )
    walls = shapely.union(hall.boundary, shapely.LineString([(9.8, 0.0), (9.8, 0.5)]))
    mapped = GridPolyMap.from_polygons(
        typed_regions(shapely.difference(hall, shadow), walls), CELL_M
    )
    truth = np.array([10.0 * math.cos(step / 2), 10.0 * math.sin(step / 2), 0.0])
    own = transform_map(_corridor_map(), inverse(truth))  # the other's map, its own frame
    assert unseen(viewer, other, truth, Room(mapped)) == 6  # beside its body: contradicted
    assert unseen(viewer, other, truth, Room(mapped), Room(own)) == 0
    assert contradictions(viewer, other, truth, (Room(mapped), Room(own))) == 0
    nearer = truth - np.array([5.0, 0.0, 0.0])
    own_nearer = transform_map(_corridor_map(), inverse(nearer))
    assert unseen(viewer, other, nearer, Room(mapped), Room(own_nearer)) == 6


def test_sightings_count_in_places_not_moments():
    """A robot seen six times standing in one place tells a frame from its rotations
    about that place no better than seen once; seen in three places 1.5 m apart, no
    quarter turn about any point explains them all."""
    room = box(-1, -8, 16, 9)
    hall = GridPolyMap.from_polygons(typed_regions(room, room.boundary), CELL_M)
    a, still, moving = Track(), Track(), Track()
    for k in range(6):
        there = (5.0, 1.5 * (k // 2))  # two moments in each of three places
        a.add(Sighting(float(k), (0.0, 0.0, 0.0), profile_with_a_robot_at(there)))
        moving.add(Sighting(float(k), (*there, 0.0)))
    b = Track()
    for k in range(6):
        still.add(Sighting(float(k), (5.0, 0.0, 0.0)))
        b.add(Sighting(float(k), (0.0, 0.0, 0.0), profile_with_a_robot_at((5.0, 0.0))))
    identity = (0.0, 0.0, 0.0)
    assert seen(b, still, identity, no_wall_test(hall)) == 6
    assert distinct_places(mutual_seen(b, still, identity, (hall, hall))) == 1
    assert seen(a, moving, identity, no_wall_test(hall)) == 6
    assert distinct_places(mutual_seen(a, moving, identity, (hall, hall))) == 3


def _seen_once(hall, at_xy, return_xy, **rule) -> int:
    """A viewer at the origin whose scan has a return at ``return_xy``; the frame puts
    the other robot at ``at_xy``: sightings counted by ``seen_where`` with ``rule``."""
    identity = (0.0, 0.0, 0.0)
    viewer, other = Track(), Track()
    viewer.add(Sighting(0.5, identity, profile_with_a_robot_at(return_xy, clear_m=45.0)))
    other.add(Sighting(0.0, (*at_xy, 0.0)))
    other.add(Sighting(1.0, (*at_xy, 0.0)))
    return len(seen_where(viewer, other, identity, no_wall_test(hall), **rule))


def test_a_wall_return_far_away_is_no_sighting_a_robot_clear_of_walls_is():
    """A 2.8-degree sector places its return anywhere across d x 0.049 m: 1.46 m at 30 m.
    A wall's return at 30 m, its sector's centre 0.6-0.73 m from the wall, passed the
    former test of the centre alone (a wrong frame was committed so); the sector's arc
    reaches the wall. A robot in the middle of the hall at 12 and 25 m is still seen."""
    hall_box = box(-1, -3, 40, 3)
    hall = GridPolyMap.from_polygons(typed_regions(hall_box, hall_box.boundary), CELL_M)
    former = {"max_range_m": math.inf, "arc": False}
    fooled = 0
    for x_m in np.arange(28.0, 32.0, 0.05):  # returns on the wall y = 3 m, far away
        on_wall = (float(x_m), 3.0 - 0.02)
        near = (float(x_m), 2.4)  # where a wrong frame puts the robot: 0.6 m off the wall
        if _seen_once(hall, near, on_wall, **former):
            fooled += 1
            assert _seen_once(hall, near, on_wall) == 0, x_m
    assert fooled >= 5  # the former rule took some of those returns for a robot
    for x_m in (12.0, 25.0):
        assert _seen_once(hall, (x_m, 0.0), (x_m, 0.0)) == 1, x_m
        assert _seen_once(hall, (x_m, 0.0), (x_m, 0.0), max_range_m=x_m - 1.0) == 0


def _scan(pose, others) -> np.ndarray:
    """Returns of a 2-degree, 30 m lidar at ``pose`` in the ring, other robots as discs,
    in the robot frame."""
    walls = shapely.union_all(
        [RING.boundary, *(shapely.Point(o).buffer(ROBOT_RADIUS_M) for o in others)]
    )
    a = np.radians(np.arange(0, 360, 2.0))
    p = np.asarray(pose[:2])
    rays = shapely.linestrings(
        [[p, p + 30 * np.array([math.cos(b), math.sin(b)])] for b in a + pose[2]]
    )
    out = []
    for ray in rays:
        hit = shapely.intersection(ray, walls)
        if hit.is_empty:
            continue
        pts = shapely.get_coordinates(hit)
        out.append(pts[np.argmin(np.hypot(*(pts - p).T))])
    return transform_points(inverse(np.asarray(pose, float)), np.array(out))


def _path(points, t) -> np.ndarray:
    """(x, y, heading) along the polyline ``points`` at fractions ``t`` of its length."""
    pts = np.asarray(points, float)
    seg = np.diff(pts, axis=0)
    cum = np.concatenate([[0], np.cumsum(np.hypot(*seg.T))])
    d = t * cum[-1]
    k = np.clip(np.searchsorted(cum, d, side="right") - 1, 0, len(seg) - 1)
    w = (d - cum[k]) / np.hypot(*seg[k].T)
    xy = pts[k] + w[:, None] * seg[k]
    return np.column_stack([xy, np.arctan2(seg[k, 1], seg[k, 0])])


def test_a_symmetric_ring_is_merged_at_its_true_frame_once_sightings_rule_out_the_images():
    """A's stretch (south half) and B's (west half) fit at the truth and at quarter
    turns of it. A drives the south, east and north corridors while B drives the west one;
    each sends clear profiles. Every rotated image puts B where A looked (or A where B
    looked) and saw nothing; the truth does not."""
    a_map = GridPolyMap.from_polygons(
        typed_regions(shapely.intersection(RING, box(-1, -1, 21, 11)), RING.boundary), CELL_M
    )
    b_world = GridPolyMap.from_polygons(
        typed_regions(shapely.intersection(RING, box(-1, -1, 11, 21)), RING.boundary), CELL_M
    )
    to_b = np.array([3.0, 1.0, 0.7])  # B's frame: the world moved by this
    truth = inverse(to_b)  # B's frame in A's (the world's)
    plain = match_maps(a_map, transform_map(b_world, to_b))
    assert not plain.accepted and "ambiguous" in plain.reason, plain.summary()

    times = np.arange(0.0, 60.0, 1.0)
    a_pose = _path([(5, 1), (19, 1), (19, 19), (5, 19)], times / 60.0)
    b_pose = _path([(1, 17), (1, 3)], times / 60.0)
    a_track, b_track = Track(), Track()
    for t, pa, pb in zip(times, a_pose, b_pose, strict=True):
        a_track.add(Sighting(t, tuple(pa), clear_profile(_scan(pa, [pb[:2]]))))
        own = compose(to_b, pb)  # B speaks in its own frame
        b_track.add(Sighting(t, tuple(own), clear_profile(_scan(pb, [pa[:2]]))))

    assert contradictions(a_track, b_track, truth) == 0
    images = [r[0] for r in plain.refined if frame_error(r[0], truth)[1] > 1.5]
    assert len(images) >= 2, "the ring's quarter and half turns are among the refined poses"
    assert sum(contradictions(a_track, b_track, p) >= MIN_CONTRADICTIONS for p in images) >= 2

    def contradicts(frame) -> bool:
        return contradictions(a_track, b_track, frame) >= MIN_CONTRADICTIONS

    m = match_maps(a_map, transform_map(b_world, to_b), contradicts)
    assert m.accepted, m.summary()
    err_m, err_rad = frame_error(m.pose, truth)
    assert err_m < 0.1 and err_rad < math.radians(1.0)
    assert m.contradicted >= 2


def test_a_pose_every_sighting_contradicts_is_never_accepted():
    a_map = GridPolyMap.from_polygons(
        typed_regions(shapely.intersection(RING, box(-1, -1, 21, 11)), RING.boundary), CELL_M
    )
    b_map = GridPolyMap.from_polygons(
        typed_regions(shapely.intersection(RING, box(-1, 5, 11, 21)), RING.boundary), CELL_M
    )
    plain = match_maps(a_map, b_map)
    silent = match_maps(a_map, b_map, lambda f: False)
    assert (silent.accepted, silent.reason) == (plain.accepted, plain.reason)
    everything = match_maps(a_map, b_map, lambda f: True)
    assert not everything.accepted and "contradicted" in everything.reason
    # past the best PEAKS peaks the search's next ones are tried, all of them here
    assert everything.contradicted == everything.candidates > PEAKS


def test_when_sightings_contradict_every_best_peak_the_next_peaks_are_refined():
    """The search's best PEAKS peaks all contradicted (here: poses put in front of the
    real ones): the next peaks are refined, and the true frame among them is found."""
    a_map = GridPolyMap.from_polygons(
        typed_regions(shapely.intersection(RING, box(-1, -1, 21, 11)), RING.boundary), CELL_M
    )
    b_world = GridPolyMap.from_polygons(
        typed_regions(shapely.intersection(RING, box(-1, -1, 11, 21)), RING.boundary), CELL_M
    )
    to_b = np.array([3.0, 1.0, 0.7])
    truth = inverse(to_b)
    decoys = [(1e6, np.array([3.0 * k, 2.0, 0.5])) for k in range(PEAKS)]

    def search(va, vb):
        return decoys + coarse_to_fine(va, vb)

    def contradicts(frame) -> bool:  # every pose but the truth
        err_m, err_rad = frame_error(frame, truth)
        return err_m > 1.0 or err_rad > math.radians(5.0)

    m = match_maps(a_map, transform_map(b_world, to_b), contradicts, search=search)
    assert m.contradicted >= PEAKS
    err_m, err_rad = frame_error(m.pose, truth)
    assert m.accepted and err_m < 0.1 and err_rad < math.radians(1.0), m.summary()


def test_a_frame_is_refused_while_an_image_of_it_under_a_symmetry_of_a_map_is_possible():
    """A has mapped the whole ring: it fits itself after every quarter turn, so B fits A
    at each image of the true frame, however little B has seen. The frame stands only
    once every image is ruled out (here by sightings)."""
    from polyswarm.frames.mapmatch import _symmetric_images, _view

    whole = GridPolyMap.from_polygons(typed_regions(RING, RING.boundary), CELL_M)
    part = GridPolyMap.from_polygons(
        typed_regions(shapely.intersection(RING, box(-1, -1, 11, 21)), RING.boundary), CELL_M
    )
    to_b = np.array([3.0, 1.0, 0.7])
    truth = inverse(to_b)
    a, b = _view(whole), _view(transform_map(part, to_b))
    why = _symmetric_images(a, b, truth, None)
    assert why.startswith("ambiguous: the maps are symmetric"), why

    def images_contradicted(frame) -> bool:
        return frame_error(frame, truth)[0] > 1.0

    assert _symmetric_images(a, b, truth, images_contradicted) == ""
    assert _symmetric_images(a, b, truth, lambda f: False).startswith("ambiguous")


def test_poses_from_before_a_large_correction_are_forgotten():
    from polyswarm.frames.sighting import SIGHTING_SLACK_M
    from polyswarm.slam.follow import CorrectionOp, largest_move_m

    # keyframe 3 moved 30 mm and 4 turned 0.1 rad (counted 0.5 m at 5 m): the largest
    op = CorrectionOp(2.0, 7, 8, ((3, (30, -40, 0)), (4, (0, 0, 10_000))), 0)
    assert math.isclose(largest_move_m(op), 0.5)
    assert largest_move_m(op) > SIGHTING_SLACK_M
    t = Track()
    for s in range(5):
        t.add(Sighting(float(s), (0.0, 0.0, 0.0)))
    assert len(t.since(2.0)) == 3 and len(t.until(2.0)) == 3


def test_a_track_moved_into_another_frame_keeps_its_times_and_profiles():
    t = Track()
    t.add(Sighting(1.0, (1.0, 0.0, 0.5), bytes(SECTORS)))
    (s,) = t.moved((2.0, 3.0, math.pi / 2))._items
    assert s.t_s == 1.0 and s.clear == bytes(SECTORS)
    assert np.allclose(s.pose, (2.0, 4.0, 0.5 + math.pi / 2))
