"""The pure ray caster and the keyframe polygon on a square room checkable by hand."""

import math
from dataclasses import replace

import numpy as np
import pytest

from polyswarm.polymap import GridPolyMap, VectorType
from polyswarm.raycast import cast_rays
from polyswarm.slam.keyframe import keyframe_polygon
from polyswarm.slam.scan import NO_RETURN_SHARE, LaserScan, scan_to_points

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
    # never beyond NO_RETURN_SHARE of the sensor's range
    short = LaserScan(np.array([np.inf] * 3), 0.0, 0.1, 0.05, 2.0)
    far = np.hypot(*scan_to_points(short, 0.2, no_return_free_m=5.0).xy[0])
    assert far == pytest.approx(NO_RETURN_SHARE * 2.0)


def test_keyframe_of_a_square_room_is_the_room():
    angles = np.linspace(-np.pi, np.pi, 721)[:-1]
    ranges = cast_rays((2.0, 2.0), angles, STARTS, ENDS)
    scan = LaserScan(ranges, -np.pi, angles[1] - angles[0], 0.05, 30.0)
    kf = keyframe_polygon(scan_to_points(scan), (2.0, 2.0, 0.0), max_gap_m=0.5)
    assert (kf.shell.types == VectorType.OBSTACLE).all()  # 360 degrees: no sensor centre
    pmap = GridPolyMap(2.0).merge(kf).map
    assert pmap.explored_area() == pytest.approx(16.0, rel=1e-3)


def test_keyframe_with_a_gap_closes_through_the_sensor():
    inf = np.inf
    scan = LaserScan(np.array([2.0, 2.0, inf, inf, inf, 2.0, 2.0]), -0.6, 0.2, 0.05, 30.0)
    kf = keyframe_polygon(scan_to_points(scan), (1.0, 0.0, 0.0))
    t = kf.shell.types
    assert len(kf.shell) == 8
    # gap beams and the two centre vectors: frontier
    assert t.tolist() == [0, 1, 1, 1, 1, 0, 1, 1]
    assert np.allclose(kf.shell.xy[-1], (1.0, 0.0))
    kf.validate()


@pytest.mark.parametrize("missing", [np.inf, np.nan, 0.0])
def test_an_isolated_dropout_between_returns_is_left_out(missing):
    """An RPLIDAR's failed reading is +inf like a beam with no return: read as free space
    it would cut through the wall its neighbours see."""
    r = np.full(12, 2.0)
    r[5] = missing
    scan = LaserScan(r, -0.6, 0.1, 0.12, 3.5)
    convention = {0.0: "zero"}.get(missing, "nan" if np.isnan(missing) else "inf")
    pts = scan_to_points(scan, 0.2, no_return_free_m=1.5, out_of_range=convention)
    assert len(pts.xy) == 11 and pts.valid.all()
    assert np.allclose(np.hypot(*pts.xy.T), 2.0)


def test_a_run_of_zeros_from_an_lds01_is_no_return_and_free_space():
    r = np.full(360, 2.0)
    r[100:140] = 0.0  # an open door: the LDS-01 driver reports 0.0
    scan = LaserScan(r, 0.0, 2 * np.pi / 360, 0.12, 3.5)
    pts = scan_to_points(scan, 0.2, no_return_free_m=1.5, out_of_range="zero")
    d = np.hypot(*pts.xy.T)
    assert np.count_nonzero(~pts.valid) == 40
    assert np.allclose(d[~pts.valid], 1.5)  # free space out to 1.5 m (below half of 3.5)
    # with the +inf convention a zero is not "no return": unknown, a short frontier point
    other = scan_to_points(scan, 0.2, no_return_free_m=1.5, out_of_range="inf")
    assert np.allclose(np.hypot(*other.xy.T)[~other.valid], 0.2)


def test_a_lidar_mounted_backwards_keeps_its_fan_in_one_piece():
    """270 degrees with a yaw of pi: the unseen wedge is ahead, and the polygon closes
    through the sensor there, not across it."""
    angles = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 271)
    scan = LaserScan(np.full(271, 1.5), angles[0], angles[1] - angles[0], 0.05, 30.0)
    pts = scan_to_points(scan, mount=(0.0, 0.0, np.pi, False))
    kf = keyframe_polygon(pts, (2.0, 2.0, 0.0), max_gap_m=0.5)
    kf.validate()
    t = kf.shell.types
    assert np.count_nonzero(t == VectorType.FRONTIER) == 2  # the two vectors to the centre
    area = 0.5 * 1.5**2 * 1.5 * np.pi  # a 270 degree sector of radius 1.5 m
    assert GridPolyMap(2.0).merge(kf).map.explored_area() == pytest.approx(area, rel=0.01)


def test_deskewing_puts_a_turning_robots_sweep_back_in_one_frame():
    """A 360 beam, 5 Hz sweep in a 4 m room while turning at 1 rad/s: the raw beams smear
    0.2 rad; moved with the robot's motion per beam they fall on the walls again."""
    from polyswarm.slam.scan import deskew_motion

    n, w, sweep = 360, 1.0, 0.2
    dt = sweep / n
    angles = -np.pi + np.arange(n) * 2 * np.pi / n
    end_heading = 0.7
    heading = end_heading - w * (sweep - dt - np.arange(n) * dt)  # at each beam
    ranges = np.array(
        [
            cast_rays((2.0, 2.0), [a + h], STARTS, ENDS)[0]
            for a, h in zip(angles, heading, strict=True)
        ]
    )
    scan = LaserScan(ranges, angles[0], angles[1] - angles[0], 0.05, 30.0, 10.0, dt, sweep)

    def odom_at(t):
        return np.stack(
            [np.full(len(t), 2.0), np.full(len(t), 2.0), end_heading - w * (scan.end_stamp - t)],
            axis=1,
        )

    motion = deskew_motion(scan, odom_at)
    skewed = keyframe_polygon(scan_to_points(scan), (2.0, 2.0, end_heading), 0.5)
    fixed = keyframe_polygon(scan_to_points(scan, motion=motion), (2.0, 2.0, end_heading), 0.5)
    fixed.validate()

    def wall_error(poly):
        xy = poly.shell.xy
        return np.min(np.abs(np.stack([xy[:, 0], 4 - xy[:, 0], xy[:, 1], 4 - xy[:, 1]])), axis=0)

    assert wall_error(fixed).max() < 1e-6
    assert wall_error(skewed).max() > 0.2
    assert deskew_motion(LaserScan(ranges, angles[0], 0.01, 0.05, 30.0), odom_at) is None


def test_a_run_of_zeros_between_returns_too_close_to_measure_is_not_free_space():
    """A TurtleBot3 brushing a wall: the LDS-01 reads below its 0.12 m minimum as 0.0,
    the same as no return. Between returns at 0.2-0.3 m that run is the wall itself;
    read as free space it cut 2.8 m through it."""
    r = np.full(360, 2.0)
    r[80:100] = 0.25  # the wall, close
    r[100:120] = 0.0  # closer still: below range_min
    r[120:140] = 0.25
    scan = LaserScan(r, 0.0, 2 * np.pi / 360, 0.12, 3.5)
    pts = scan_to_points(scan, 0.2, no_return_free_m=1.5, out_of_range="zero")
    d = np.hypot(*pts.xy.T)
    assert np.count_nonzero(~pts.valid) == 20
    assert np.allclose(d[~pts.valid], 0.2)  # unknown: a short frontier point, not 1.5 m
    # the same run between far returns is an open door: free space
    far = r.copy()
    far[80:100] = far[120:140] = 2.0
    pts = scan_to_points(replace(scan, ranges=far), 0.2, no_return_free_m=1.5, out_of_range="zero")
    assert np.allclose(np.hypot(*pts.xy.T)[~pts.valid], 1.5)
