"""CARMEN logs, TUM files, odometry noise and trajectory metrics."""

from __future__ import annotations

import gzip
import math

import numpy as np
import pytest

from polyswarm.errors import DataFormatError
from polyswarm.evaluation.coverage import time_to_coverage
from polyswarm.evaluation.trajectory import align_se2, ate_rmse, max_errors, rpe, travelled
from polyswarm.io.carmen import read_carmen, real_odometry
from polyswarm.io.tum import read_tum, write_tum
from polyswarm.se2 import compose, wrap
from polyswarm.slam.odometry import IncrementNoise, noisy_odometry

LOG = """# CARMEN Logfile
PARAM robot_front_laser_max 30.0 nohost 0
PARAM laser_front_laser_fov 3.14159 nohost 0
ODOM 0.0 0.0 0.0 0.1 0.0 0.0 1.0 host 1.0
SOMETHING unknown line with words
FLASER 5 1.0 2.0 30.0 3.0 4.0 0.5 0.5 0.1 0.5 0.5 0.1 10.0 host 10.0
FLASER 5 1.0 2.0 3.0 3.0 4.0 1.5 0.5 0.1 1.5 0.5 0.1 11.0 host 11.0
ROBOTLASER1 0 -1.5708 3.14159 0.785398 30.0 0.01 0 5 1.0 1.0 1.0 1.0 1.0 0 \
2.5 0.5 0.2 2.5 0.5 0.2 0 0 0 0 0 12.0 host 12.0
"""


def test_reads_flaser_robotlaser_odom_and_params(tmp_path):
    p = tmp_path / "a.log.gz"
    with gzip.open(p, "wt") as f:
        f.write(LOG)
    log = read_carmen(p)
    assert len(log.scans) == 3 and log.odometry.shape == (1, 4)
    s = log.scans[0]
    assert s.scan.range_max == 30.0
    assert s.scan.angle_min == pytest.approx(-math.pi / 2, abs=1e-5)
    assert s.scan.angle_increment == pytest.approx(math.pi / 4, abs=1e-5)  # odd count
    assert np.allclose(s.pose, [0.5, 0.5, 0.1])
    assert math.isclose(s.stamp, 10.0) and not log.timestamps_synthesized
    assert log.scans[2].scan.angle_increment == pytest.approx(0.785398)
    assert np.allclose(log.scans[2].pose, [2.5, 0.5, 0.2])


@pytest.mark.parametrize(
    ("line", "match"),
    [
        ("FLASER x 1 2", "bad count"),
        ("FLASER 3 1.0 2.0", "needs"),
        ("FLASER 2 1.0 abc 0 0 0 0 0 0 1 h 1", "ranges"),
        ("ODOM 1 2", "ODOM"),
        ("FLASER 2 1.0 nan 0 0 0 0 0 0 1 h 1", "non-finite"),
    ],
)
def test_malformed_lines_name_their_line_number(tmp_path, line, match):
    p = tmp_path / "b.log"
    p.write_text("# header\nPARAM a b\n" + line + "\n")
    with pytest.raises(DataFormatError, match=f"line 3: .*{match}"):
        read_carmen(p)


def test_useless_timestamps_are_synthesized(tmp_path):
    lines = [f"FLASER 3 1 1 1 {k} 0 0 {k} 0 0 0.0 h 0.0" for k in range(4)]
    p = tmp_path / "c.log"
    p.write_text("\n".join(lines) + "\n")
    log = read_carmen(p)
    assert log.timestamps_synthesized
    assert [s.stamp for s in log.scans] == [0.0, 1.0, 2.0, 3.0]


def test_tum_round_trip(tmp_path):
    poses = np.array([[0, 0, 0], [1, 2, 0.5], [3, -1, -2.0]])
    write_tum(tmp_path / "t.tum", np.array([0.0, 1.0, 2.0]), poses)
    t, back = read_tum(tmp_path / "t.tum")
    assert np.allclose(back, poses, atol=1e-6) and np.allclose(t, [0, 1, 2])


def circle_trajectory(n=200):
    a = np.linspace(0, 2 * np.pi, n)
    return np.stack([5 * np.cos(a), 5 * np.sin(a), wrap(a + np.pi / 2)], axis=1)


def test_ate_is_zero_for_a_moved_copy_and_alignment_recovers_it():
    ref = circle_trajectory()
    moved = np.array([compose((3.0, -2.0, 0.7), p) for p in ref])
    R, t = align_se2(moved[:, :2], ref[:, :2])
    assert np.allclose(moved[:, :2] @ R.T + t, ref[:, :2], atol=1e-9)
    assert ate_rmse(moved, ref) == pytest.approx(0.0, abs=1e-9)
    assert ate_rmse(moved, ref, align=False) > 1.0


def test_rpe_and_max_errors():
    ref = circle_trajectory()
    assert rpe(ref, ref, 1.0)["trans_mean_m"] == pytest.approx(0.0, abs=1e-12)
    est = ref.copy()
    est[:, 0] += 0.1
    assert max_errors(est, ref) == pytest.approx((0.1, 0.0))
    assert travelled(ref)[-1] == pytest.approx(2 * np.pi * 5, rel=1e-3)


def test_odometry_noise_is_seeded_and_zero_noise_is_exact():
    ref = circle_trajectory()
    quiet = noisy_odometry(ref, IncrementNoise(0, 0, 0, 0), seed=1)
    assert np.allclose(quiet, ref, atol=1e-9)
    a, b = noisy_odometry(ref, IncrementNoise(), 4), noisy_odometry(ref, IncrementNoise(), 4)
    assert np.array_equal(a, b)
    assert ate_rmse(a, ref, align=False) > 0.05


def test_shared_logs_have_the_documented_scan_counts(shared_data):
    counts = {"aces": 440, "csail": 406, "freiburg-101": 292, "orebro": 237}
    for name, n in counts.items():
        log = read_carmen(shared_data / "logs" / f"{name}-corrected.log.gz")
        assert len(log.scans) == n
        inc = log.scans[0].scan.angle_increment
        assert math.degrees(inc) in (pytest.approx(1.0, abs=1e-3), pytest.approx(0.5, abs=1e-3))


def test_time_to_coverage_is_the_first_time_the_fraction_is_reached():
    curve = [(0.0, 0.0), (10.0, 0.5), (20.0, 0.9), (30.0, 0.89), (40.0, 0.995)]
    assert time_to_coverage(curve, 0.9) == 20.0  # reached exactly; the dip at 30 s after it
    assert time_to_coverage(curve, 0.99) == 40.0
    assert time_to_coverage(curve, 1.0) is None  # never reached
    assert time_to_coverage([], 0.5) is None


def test_phantom_obstacles_are_the_length_of_walls_that_are_not_there():
    from polyswarm.evaluation.maps import phantom_obstacles, wall_distance

    room = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], dtype=float)
    ws, we = room, np.roll(room, -1, axis=0)
    starts = np.array([[0.5, 0.01], [1.0, 1.0]])  # along the south wall; 1 m inside
    ends = np.array([[2.5, 0.01], [2.5, 1.0]])
    assert phantom_obstacles(starts, ends, ws, we, far_m=0.3) == pytest.approx(1.5)
    assert phantom_obstacles(starts[:1], ends[:1], ws, we, far_m=0.3) == 0.0
    # the mean wall distance weighs both by length: (2 x 0.01 + 1.5 x 1.0) / 3.5
    assert wall_distance(starts, ends, ws, we) == pytest.approx((0.02 + 1.5) / 3.5)


def test_reachable_free_space_is_what_the_footprint_sweeps_less_the_noise_band():
    import shapely

    from polyswarm.evaluation.coverage import coverage_tolerance, reachable_free

    # a 4 x 4 m room, and through a 0.3 m gap a 1 x 1 m closet no 0.2 m robot enters
    room = shapely.box(0, 0, 4, 4)
    closet = shapely.box(4.2, 1.0, 5.2, 2.0)
    gap = shapely.box(3.9, 1.35, 4.3, 1.65)
    free = shapely.union_all([room, closet, gap])
    swept = reachable_free(free, 0.2, [(1.0, 1.0, 0.0)])
    # the room less the corners the disc cannot reach (r^2 - pi r^2 / 4 each); not the closet
    corners = 4 * (0.2**2 - math.pi * 0.2**2 / 4)
    assert swept.area == pytest.approx(16.0 - corners, abs=0.03)  # corners as 4-gons
    assert not swept.intersects(closet)
    tol = coverage_tolerance(0.01, 0.0175)  # two sigma of an LDS-01 at 2 m
    assert tol == pytest.approx(2 * (0.01 + 0.0175 * 2.0))
    assert reachable_free(free, 0.2, [(1.0, 1.0)], tol).area == pytest.approx(
        (4 - 2 * tol) ** 2, rel=0.005
    )
    # a start nowhere near the free space: nothing is reachable
    assert reachable_free(free, 0.2, [(10.0, 10.0)]).is_empty


def flaser(x: float, y: float, th: float, t: float) -> str:
    pose = f"{x} {y} {th}"
    return f"FLASER 5 1.0 2.0 3.0 3.0 4.0 {pose} {pose} {t} host {t}"


def odom(x: float, y: float, th: float, t: float) -> str:
    return f"ODOM {x} {y} {th} 0 0 0 {t} host {t}"


def test_real_odometry_chains_the_wheel_motion_from_each_scans_anchor(tmp_path):
    """Each scan is followed by an ODOM line at its corrected pose; the ODOM lines up to
    the next scan integrate the wheels from there. The wheels say: 1.1 m straight ahead,
    then a 0.2 rad turn and 0.5 m; the corrected poses say 1.0 m and 0.6 m."""
    lines = [
        flaser(0, 0, 0, 1),
        odom(0, 0, 0, 1.1),
        odom(0.6, 0, 0, 1.5),
        odom(1.1, 0, 0, 1.9),
        flaser(1.0, 0, 0, 2),
        odom(1.0, 0, 0, 2.1),
        odom(1.0, 0, 0.2, 2.5),
        odom(1.0 + 0.5 * math.cos(0.2), 0.5 * math.sin(0.2), 0.2, 2.9),
        flaser(1.6, 0.1, 0.1, 3),
        odom(1.6, 0.1, 0.1, 3.1),
    ]
    p = tmp_path / "real.log"
    p.write_text("\n".join(lines) + "\n")
    od = real_odometry(read_carmen(p))
    assert np.allclose(od[0], [0, 0, 0])
    assert np.allclose(od[1], [1.1, 0, 0])  # the wheels' 1.1 m, not the corrected 1.0
    expected = compose(np.array([1.1, 0, 0]), [0.5 * math.cos(0.2), 0.5 * math.sin(0.2), 0.2])
    assert np.allclose(od[2], expected)


def test_a_log_with_only_the_anchoring_odom_lines_has_no_real_odometry(tmp_path):
    lines = [flaser(0, 0, 0, 1), odom(0, 0, 0, 1.1), flaser(1, 0, 0, 2), odom(1, 0, 0, 2.1)]
    lines += [flaser(2, 0, 0, 3), odom(2, 0, 0, 3.1)]
    p = tmp_path / "anchors.log"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFormatError, match="no raw ODOM"):
        real_odometry(read_carmen(p))


def test_ghost_wall_share_on_walls_drawn_by_hand():
    import numpy as np

    from polyswarm.evaluation.maps import ghost_wall_share

    live_s = np.array([[0.0, 0.0], [0.0, 1.0]])
    live_e = np.array([[1.0, 0.0], [1.0, 1.0]])
    ref_s, ref_e = np.array([[0.0, 0.05]]), np.array([[1.0, 0.05]])
    # the first wall lies 5 cm from the reference's, the second 95 cm: half is a ghost
    assert ghost_wall_share(live_s, live_e, ref_s, ref_e, 0.1) == pytest.approx(0.5)
    assert ghost_wall_share(live_s[:1], live_e[:1], ref_s, ref_e, 0.1) == 0.0
    assert ghost_wall_share(live_s, live_e, ref_s[:0], ref_e[:0], 0.1) == 1.0
