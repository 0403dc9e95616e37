"""The pure ray caster and the keyframe polygon on a square room checkable by hand."""

import math

import numpy as np
import pytest

from polyswarm.keyframe import keyframe_polygon
from polyswarm.polymap import GridPolyMap, VectorType
from polyswarm.raycast import cast_rays
from polyswarm.scan import LaserScan, scan_to_points

# a 4 m x 4 m room, walls as segments
ROOM = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], dtype=float)
STARTS, ENDS = ROOM, np.roll(ROOM, -1, axis=0)


def test_ray_at_a_wall_two_metres_away():
    r = cast_rays((2.0, 2.0), np.array([0.0, np.pi / 2, np.pi, -np.pi / 2]), STARTS, ENDS)
    assert np.allclose(r, 2.0, atol=1e-12)


def test_diagonal_ray_and_out_of_range():
    r = cast_rays((1.0, 1.0), np.array([np.pi / 4]), STARTS, ENDS)
    assert r[0] == pytest.approx(3 * math.sqrt(2))
    assert np.isinf(cast_rays((1.0, 1.0), np.array([np.pi / 4]), STARTS, ENDS, max_range=2.0))[0]


def test_chunking_does_not_change_results(monkeypatch):
    import polyswarm.raycast as rc

    angles = np.linspace(-np.pi, np.pi, 1000)
    a = cast_rays((1.3, 2.1), angles, STARTS, ENDS)
    monkeypatch.setattr(rc, "CHUNK_RAYS", 7)
    assert np.array_equal(a, cast_rays((1.3, 2.1), angles, STARTS, ENDS))


def test_scan_to_points_turns_invalid_beams_into_short_frontier_points():
    scan = LaserScan(np.array([1.0, np.inf, np.nan, 0.01, 30.0, 2.0]), 0.0, 0.1, 0.05, 30.0)
    pts = scan_to_points(scan, frontier_range_m=0.2)
    assert pts.valid.tolist() == [True, False, False, False, False, True]
    assert np.allclose(np.hypot(*pts.xy.T), [1.0, 0.2, 0.2, 0.2, 0.2, 2.0])


def test_a_beam_with_no_return_crossed_free_space_a_dropout_did_not():
    # inf and 30.0 (= range_max) returned nothing within range; NaN and 0.01 (< range_min)
    # are dropouts
    scan = LaserScan(np.array([1.0, np.inf, np.nan, 0.01, 30.0, 2.0]), 0.0, 0.1, 0.05, 30.0)
    pts = scan_to_points(scan, frontier_range_m=0.2, no_return_free_m=1.5)
    assert pts.valid.tolist() == [True, False, False, False, False, True]
    assert np.allclose(np.hypot(*pts.xy.T), [1.0, 1.5, 0.2, 0.2, 1.5, 2.0])
    # never beyond half the sensor's range
    short = LaserScan(np.array([np.inf]), 0.0, 0.1, 0.05, 2.0)
    assert np.hypot(*scan_to_points(short, 0.2, no_return_free_m=5.0).xy[0]) == pytest.approx(1.0)


def test_keyframe_of_a_square_room_is_the_room():
    angles = np.linspace(-np.pi, np.pi, 721)[:-1]
    ranges = cast_rays((2.0, 2.0), angles, STARTS, ENDS)
    scan = LaserScan(ranges, -np.pi, angles[1] - angles[0], 0.05, 30.0)
    kf = keyframe_polygon(scan_to_points(scan), (2.0, 2.0, 0.0), max_gap_m=0.5)
    assert (kf.shell.types == VectorType.OBSTACLE).all()  # 360 degrees: no sensor centre
    pmap = GridPolyMap(2.0).merge(kf).map
    assert pmap.explored_area() == pytest.approx(16.0, rel=1e-3)


def test_keyframe_with_a_gap_closes_through_the_sensor():
    scan = LaserScan(np.array([2.0, 2.0, np.inf, 2.0, 2.0]), -0.4, 0.2, 0.05, 30.0)
    kf = keyframe_polygon(scan_to_points(scan), (1.0, 0.0, 0.0))
    t = kf.shell.types
    assert len(kf.shell) == 6
    assert t.tolist() == [0, 1, 1, 0, 1, 1]  # gap beams and the two centre vectors: frontier
    assert np.allclose(kf.shell.xy[-1], (1.0, 0.0))
    kf.validate()
