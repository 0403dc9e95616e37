"""Map-to-map registration without a pose prior, on buildings drawn by hand."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import shapely
import shapely.affinity
from shapely.geometry import box

from polyswarm.frames.estimate import MIN_SEEN, FrameEstimate
from polyswarm.frames.mapmatch import MapMatch, fit_at, frame_error, match_maps, transform_map
from polyswarm.polymap import GridPolyMap
from polyswarm.se2 import inverse
from tests.conftest import CELL_M, building, seen_map, typed_regions


def test_transform_map_moves_the_explored_space_and_keeps_its_area():
    m = seen_map(box(-10, -10, 30, 10))
    pose = np.array([3.0, -2.0, 0.7])
    moved = transform_map(m, pose)
    assert moved.explored_area() == pytest.approx(m.explored_area(), rel=1e-6)
    back = transform_map(moved, inverse(pose))
    assert shapely.symmetric_difference(back.explored_region(), m.explored_region()).area < 1e-3


@pytest.mark.parametrize(
    "pose", [(4.0, -3.0, 2.1), (-7.5, 12.0, -0.4), (0.3, 0.2, math.pi)], ids=str
)
def test_a_moved_part_of_the_building_is_found_where_it_is(pose):
    a = seen_map(box(-1, -8, 16, 9))  # the west two thirds
    b = seen_map(box(8, -8, 25, 9), pose)  # the east two thirds, in a frame at ``pose``
    m = match_maps(a, b)
    assert m.accepted, m.summary()
    err_m, err_rad = frame_error(m.pose, pose)
    assert err_m < 0.03 and err_rad < math.radians(0.3), m.summary()
    assert m.overlap_m2 > 30 and m.conflict_share < 0.01


def test_clear_space_is_what_lies_deeper_than_clear_m_inside_the_explored_space():
    """On a room turned 30 degrees (no wall along the raster), the cells counted clear
    are exactly those whose centres lie more than CLEAR_M inside: none nearer a wall."""
    from polyswarm.frames.mapmatch import CLEAR_M, RESOLUTION_M, _view

    room = shapely.affinity.rotate(box(0, 0, 4, 3), 30, origin=(0, 0))
    v = _view(GridPolyMap.from_polygons(typed_regions(room, room.boundary), CELL_M))
    ij = np.indices(v.deep.shape).reshape(2, -1).T
    centres = shapely.points((ij + 0.5) * RESOLUTION_M + v.lo)
    depth = np.where(shapely.contains(room, centres), shapely.distance(room.boundary, centres), 0)
    deep = v.deep.reshape(-1)
    assert deep.any() and depth[deep].min() > CLEAR_M
    assert not (depth > CLEAR_M + 1e-6)[~deep].any()


def test_walls_seen_on_the_other_robot_where_it_went_are_no_conflict():
    """B's robot saw A's robot eight times in the corridor: walls in the middle of it,
    where A's map is clear (A stood there). Taken for walls of the building they refuse
    the true pose; with A's path given, walls wholly within its band are no conflict."""
    pose = np.array([4.0, -3.0, 2.1])
    path = np.array([[9.0, 1.0], [12.0, 1.05], [15.0, 1.0]])  # A's, in A's frame
    seen_at = np.linspace(9.2, 14.8, 8)
    body = 0.2  # the robot's radius, m; its outline in vectors about a lidar step long
    bodies = shapely.union_all([shapely.Point(x, 1.0).buffer(body, quad_segs=2) for x in seen_at])
    house = building()
    part = shapely.difference(shapely.intersection(house, box(8, -8, 25, 9)), bodies)
    walls = shapely.union(house.boundary, bodies.boundary)
    b = transform_map(GridPolyMap.from_polygons(typed_regions(part, walls), CELL_M), inverse(pose))
    a = seen_map(box(-1, -8, 16, 9))
    at_truth = fit_at([a], b, pose)[0]["conflict_share"]
    assert at_truth > 0.1  # the bodies' outlines, in A's clear corridor
    assert fit_at([a], b, pose, paths=[path])[0]["conflict_share"] < 0.01
    # the paths only spare walls near them: a path elsewhere spares nothing
    elsewhere = fit_at([a], b, pose, paths=[path + np.array([0.0, -5.0])])[0]["conflict_share"]
    assert elsewhere == pytest.approx(at_truth)
    # a wall across the corridor where A went is the building's: it reaches out of the band
    across = shapely.difference(part, box(12.9, -0.5, 13.1, 2.5))
    walls_across = shapely.union(walls, box(12.9, -0.5, 13.1, 2.5).boundary)
    typed = typed_regions(across, walls_across)
    b_across = transform_map(GridPolyMap.from_polygons(typed, CELL_M), inverse(pose))
    assert fit_at([a], b_across, pose, paths=[path])[0]["conflict_share"] > 0.01
    assert not match_maps(a, b).accepted
    m = match_maps(a, b, a_paths=[path])
    assert m.accepted, m.summary()
    err_m, err_rad = frame_error(m.pose, pose)
    assert err_m < 0.03 and err_rad < math.radians(0.3), m.summary()


def test_maps_that_share_no_space_are_not_merged():
    a = seen_map(box(-1, -8, 10, 9))
    b = seen_map(box(12, -8, 25, 9), (2.0, 1.0, 0.5))
    m = match_maps(a, b)
    assert not m.accepted
    assert m.reason


def test_a_square_room_fits_four_ways_and_is_not_merged():
    room = box(0, 0, 6, 6)
    a = GridPolyMap.from_polygons(typed_regions(room, room.boundary), CELL_M)
    b = transform_map(a, (1.0, 2.0, 0.3))
    m = match_maps(a, b)
    assert not m.accepted
    assert "ambiguous" in m.reason or "agreeing wall" in m.reason or "overlap" in m.reason


def test_identical_rooms_in_a_row_are_ambiguous():
    """Five identical rooms off a corridor; B saw two of them: any two fit."""
    rooms = [box(5 * k, 2, 5 * k + 4, 7) for k in range(5)]
    b_all = shapely.union_all([box(0, 0, 24, 2), *rooms])
    a = GridPolyMap.from_polygons(typed_regions(b_all, b_all.boundary), CELL_M)
    part = shapely.intersection(b_all, box(4.5, -1, 14.5, 8))
    b = transform_map(
        GridPolyMap.from_polygons(typed_regions(part, b_all.boundary), CELL_M), (0, 0, 1.0)
    )
    m = match_maps(a, b)
    assert not m.accepted
    assert "ambiguous" in m.reason, m.summary()


SEEN = MIN_SEEN  # the robots saw each other where the frame puts them


def _m(pose, accepted=True) -> MapMatch:
    return MapMatch(np.asarray(pose, dtype=float), accepted, "", 50.0, 30.0, 0.9, 0.0, 0.1, 1.0)


def test_a_frame_is_committed_only_when_successive_matches_agree():
    f = FrameEstimate()
    assert f.add(_m((1.0, 2.0, 0.1)), SEEN) is None  # one match is not trusted
    assert f.add(_m((5.0, 2.0, 0.1)), SEEN) is None  # another frame: starts over
    assert f.add(_m((0.0, 0.0, 0.0), accepted=False), SEEN) is None  # refused: changes nothing
    got = f.add(_m((5.1, 2.0, 0.11)), SEEN)
    assert got is not None and np.allclose(got, (5.1, 2.0, 0.11))


def test_a_frame_is_committed_only_where_the_robots_saw_each_other():
    """Agreeing matches are not enough: in a building that looks the same after a
    quarter turn they agree on a wrong image as readily as on the truth."""
    f = FrameEstimate()
    f.add(_m((1.0, 2.0, 0.1)), 0)
    assert f.add(_m((1.0, 2.0, 0.1)), MIN_SEEN - 1) is None
    assert np.allclose(f.candidate, (1.0, 2.0, 0.1))  # where to look for the others
    assert f.add(_m((1.02, 2.0, 0.1)), MIN_SEEN) is not None


def test_silence_commits_no_frame():
    """Matches that agree however often, with the robots never seen where they put
    each other, commit nothing: in loop and cross a frame that stood 60 s uncontradicted
    was 30 m and 90 degrees off."""
    f = FrameEstimate()
    for _ in range(20):
        assert f.add(_m((1.0, 2.0, 0.1)), MIN_SEEN - 1) is None
    assert np.allclose(f.candidate, (1.0, 2.0, 0.1))


def test_sightings_single_out_a_pose_the_maps_leave_ambiguous():
    """A pose the maps also fit elsewhere (rivals, symmetric images) is proposed like an
    accepted one: only the sightings at it commit it, as they would a wrong accepted one."""
    from dataclasses import replace

    ambiguous = replace(_m((1.0, 2.0, 0.1), accepted=False), ambiguous=True)
    f = FrameEstimate()
    f.add(ambiguous, 0)
    assert f.add(ambiguous, 0) is None and len(f.run) == 2  # the maps alone: not committed
    assert np.allclose(f.candidate, (1.0, 2.0, 0.1))  # but where to look for the others
    assert f.add(ambiguous, MIN_SEEN) is not None
    g = FrameEstimate()  # a refusal for any other reason is not rescued by sightings
    g.add(_m((1.0, 2.0, 0.1), accepted=False), MIN_SEEN)
    assert g.add(_m((1.0, 2.0, 0.1), accepted=False), MIN_SEEN) is None
    assert g.run == [] and g.candidate is None


def _ev(conflict_share: float, overlap_m2: float = 50.0) -> dict:
    return {
        "overlap_m2": overlap_m2,
        "agreeing_wall_m": 30.0,
        "agreeing_share": 0.9,
        "conflict_share": conflict_share,
        "score": 300.0,
    }


@pytest.mark.parametrize(
    ("conflicts", "overlap_m2", "proposed"),
    [(0.005, 50.0, True), (0.02, 50.0, True), (0.05, 50.0, False), (0.02, 5.0, False)],
)
def test_a_pose_refused_only_for_slight_conflicts_is_proposed(conflicts, overlap_m2, proposed):
    """A map bent by drift conflicts with the other by a per cent or two at the right
    frame: refused, but proposed for sightings to confirm. More conflicts, or another
    reason to refuse, and it is not."""
    from polyswarm.frames.mapmatch import _decide

    m = _decide([(np.zeros(3), _ev(conflicts, overlap_m2))], candidates=1)
    assert m.accepted == (conflicts <= 0.01 and overlap_m2 >= 10.0)
    assert m.proposed == proposed
    f = FrameEstimate()
    f.add(m, SEEN)
    assert (f.add(m, SEEN) is not None) == proposed


def test_a_committed_frame_is_revised_by_agreeing_contradictions_only():
    f = FrameEstimate()
    f.add(_m((1.0, 0.0, 0.0)), SEEN)
    f.add(_m((1.0, 0.05, 0.0)), SEEN)
    f.add(_m((9.0, 0.0, 0.0)), SEEN)  # one contradiction: kept
    assert np.allclose(f.pose, (1.0, 0.05, 0.0)) and f.contradictions == 1
    f.add(_m((9.0, 0.1, 0.0)), SEEN)
    f.add(_m((9.1, 0.1, 0.0)), SEEN)  # three in a row that agree: the frame was wrong
    assert np.allclose(f.pose, (9.1, 0.1, 0.0)) and f.revisions == 1


@pytest.mark.parametrize("features", ["akaze", "orb"])
def test_the_peer_methods_grid_merging_finds_a_whole_moved_building(features):
    """The baseline as a baseline should work: the same whole building, moved."""
    from polyswarm.benchmarks.gridmerge import DEFAULT_THRESHOLD, Features, match_grids

    pose = (2.0, 1.0, 0.3)
    everything = box(-10, -10, 30, 10)
    g = match_grids(seen_map(everything), seen_map(everything, pose), Features(features))
    assert g.confidence >= DEFAULT_THRESHOLD
    err_m, err_rad = frame_error(g.pose, pose)
    assert err_m < 0.2 and err_rad < math.radians(1.0)


def test_parts_of_a_symmetric_ring_corridor_are_not_merged():
    """A square ring corridor looks the same after a quarter turn: B's stretch of it
    fits A's in several places without contradiction, so no frame is accepted."""
    ring = shapely.difference(box(0, 0, 20, 20), box(2, 2, 18, 18))
    a_part = shapely.intersection(ring, box(-1, -1, 21, 11))  # the south half
    b_part = shapely.intersection(ring, box(-1, 5, 11, 21))  # the north-west half
    a = GridPolyMap.from_polygons(typed_regions(a_part, ring.boundary), CELL_M)
    b = GridPolyMap.from_polygons(typed_regions(b_part, ring.boundary), CELL_M)
    m = match_maps(a, transform_map(b, (3.0, 1.0, 0.7)))
    assert not m.accepted
    assert "ambiguous" in m.reason, m.summary()


def test_the_peer_method_with_too_few_features_finds_no_frame():
    """Two TurtleBot3 maps after 5 s (tests/fixtures): ORB finds one keypoint in each,
    and OpenCV's matcher, asked for two neighbours, threw and ended `bench merge`."""
    from polyswarm.benchmarks.gridmerge import Features, match_grids
    from protocols.files import read_polymap

    fixtures = Path(__file__).parent / "fixtures"
    a = read_polymap(fixtures / "tb3_first_5s_r1.polymap")
    b = read_polymap(fixtures / "tb3_first_5s_r2.polymap")
    g = match_grids(a, b, Features.ORB)
    assert g.pose is None and g.confidence == 0.0
