"""The simulator with real pybullet in DIRECT mode, on geometry checkable by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from polyswarm.config import SimConfig, with_overrides
from polyswarm.data import WORLDS
from polyswarm.errors import SimulationError
from polyswarm.io.mapserver import read_map
from sim import PROCEDURAL, Simulation, load_world, spread_start_poses
from sim.shapes import square, walls_from_lines, world_from_walls

INNER = 0.1  # walls are 0.2 m thick around the 4 m square: inner faces 0.1 m inside


def square_room():
    return world_from_walls("square", walls_from_lines([square(0, 0, 4, 4)], 0.2), (2.0, 2.0))


def cfg(**over) -> SimConfig:
    from polyswarm.config import Config

    return with_overrides(Config(), {"sim": over}).sim


def test_square_room_gives_the_analytic_ranges():
    with Simulation(square_room(), cfg(), 1, start_poses=[(2.0, 2.0, 0.3)]) as sim:
        scan = next(iter(sim.run(0.2))).scan
    a = scan.angles + 0.3  # beam directions in the world frame
    half = 2.0 - INNER
    expect = np.minimum(half / np.abs(np.cos(a)), half / np.abs(np.sin(a)))
    err = scan.ranges - expect
    assert abs(err.mean()) < 0.002  # zero-mean noise
    assert 0.008 < err.std() < 0.012  # sigma 0.01 m
    assert np.abs(err).max() < 6 * 0.01


@pytest.mark.parametrize(
    ("convention", "is_reported"),
    [("inf", np.isposinf), ("nan", np.isnan), ("zero", lambda r: r == 0.0)],
)
def test_beams_without_a_return_are_reported_the_drivers_way(convention, is_reported):
    world = load_world("loop")
    lidar = {"range_max_m": 3.0, "dropout_prob": 0.2, "out_of_range": convention}
    with Simulation(world, cfg(lidar=lidar), 1) as sim:
        r = next(iter(sim.run(0.2))).scan.ranges
    missing = is_reported(r)
    # the corridor is longer than 3 m: some beams see nothing, and a fifth drop out
    assert 0.25 < missing.mean() < 0.85
    assert np.all(np.isfinite(r[~missing]) & (r[~missing] > 0.05) & (r[~missing] < 3.0))


def test_range_noise_grows_with_the_range_as_the_datasheet_says():
    lidar = {"noise_sigma_m": 0.0, "noise_sigma_per_m": 0.02, "fov_rad": 2 * math.pi}
    with Simulation(square_room(), cfg(lidar=lidar), 1, start_poses=[(2.0, 2.0, 0.0)]) as sim:
        errs = []
        for ev in sim.run(10.0):
            a = ev.scan.angles
            half = 2.0 - INNER
            expect = np.minimum(half / np.abs(np.cos(a)), half / np.abs(np.sin(a)))
            errs.append((ev.scan.ranges - expect) / expect)
    rel = np.concatenate(errs)
    assert 0.018 < rel.std() < 0.022  # 2 % of the range, near walls and in corners alike


def test_a_rolling_sweep_takes_its_beams_over_the_sweep_while_the_robot_turns():
    """A 5 Hz lidar turning at 1 rad/s smears 0.2 rad over a sweep: the first beam sees
    the room as it was 0.2 s before the last one."""
    lidar = {"fov_rad": 2 * math.pi, "beams": 360, "rate_hz": 5.0, "noise_sigma_m": 0.0}
    rolling = cfg(lidar=lidar | {"rolling": True}, robot={"max_angular_accel_radps2": 100.0})
    with Simulation(square_room(), rolling, 1, start_poses=[(2.0, 2.0, 0.0)]) as sim:
        sim.set_cmd(0, 0.0, 1.0)
        events = list(sim.run(1.0))
    ev = events[-1]
    s = ev.scan
    assert s.time_increment == pytest.approx(0.2 / 360)
    assert s.end_stamp == pytest.approx(s.stamp + 0.2 * 359 / 360)
    assert sim.time == pytest.approx(s.stamp + 0.2)  # published at the sweep's end
    # beam k was taken at heading theta_end - (0.2 - k dt) rad/s x 1 rad/s
    heading = ev.true_pose[2] - (0.2 - np.arange(360) * s.time_increment) * 1.0
    a = s.angles + heading
    half = 2.0 - INNER
    expect = np.minimum(half / np.abs(np.cos(a)), half / np.abs(np.sin(a)))
    assert np.abs(s.ranges - expect).max() < 0.02
    unskewed = np.minimum(
        half / np.abs(np.cos(s.angles + ev.true_pose[2])),
        half / np.abs(np.sin(s.angles + ev.true_pose[2])),
    )
    assert np.abs(s.ranges - unskewed).max() > 0.1  # the smear is real


def test_each_robot_has_its_own_systematic_odometry_error():
    noise = {
        "trans_sigma_per_sqrt_m": 0.0,
        "lateral_sigma_per_sqrt_m": 0.0,
        "rot_sigma_per_sqrt_rad": 0.0,
        "rot_sigma_per_sqrt_m": 0.0,
        "scale_sigma": 0.05,
    }
    poses = [(1.0, 1.0, 0.0), (1.0, 3.0, 0.0)]
    with Simulation(square_room(), cfg(odometry_noise=noise), 2, start_poses=poses) as sim:
        for k in (0, 1):
            sim.set_cmd(k, 0.2, 0.0)
        list(sim.run(5.0))
        ratios = [
            (r.odom[0] - 0.0) / (r.pose[0] - p[0]) for r, p in zip(sim.robots, poses, strict=True)
        ]
    assert ratios[0] != pytest.approx(ratios[1], abs=1e-3)
    assert all(0.8 < q < 1.2 and q != pytest.approx(1.0, abs=1e-4) for q in ratios)


def test_a_simulator_restored_from_a_saved_state_goes_on_where_the_old_one_was():
    """A killed simulator started again on its state: the same poses, odometry, noise
    and scans as the one that went on (json round trip, as simserve saves it)."""
    import json

    poses = [(1.0, 1.0, 0.0), (1.0, 3.0, 0.0)]
    with Simulation(square_room(), cfg(), 2, start_poses=poses) as a:
        for k in (0, 1):
            a.set_cmd(k, 0.2, 0.3)
        list(a.run(2.0))
        saved = json.loads(json.dumps(a.state()))
        went_on = list(a.run(1.0))
        with Simulation(square_room(), cfg(), 2, start_poses=poses) as b:
            b.restore(saved)
            for k in (0, 1):
                b.set_cmd(k, 0.2, 0.3)
            resumed = list(b.run(1.0))
            assert b.time == pytest.approx(a.time)
            for x, y in zip(went_on, resumed, strict=True):
                assert np.array_equal(x.scan.ranges, y.scan.ranges)
                assert np.array_equal(x.odom, y.odom) and np.array_equal(x.true_pose, y.true_pose)
        with Simulation(square_room(), cfg(), 2, start_poses=poses) as c:
            c.restore(saved, steps_ahead=1)  # later than what was sent: a whole scan later
            assert c.time > 2.0 and c.steps % c.scan_every == 0
        with (
            Simulation(square_room(), cfg(), 1, start_poses=poses[:1]) as d,
            pytest.raises(SimulationError),
        ):
            d.restore(saved)


def test_two_robots_see_each_other():
    poses = [(1.0, 2.0, 0.0), (3.0, 2.0, math.pi)]
    with Simulation(square_room(), cfg(lidar={"noise_sigma_m": 0.0}), 2, start_poses=poses) as sim:
        events = list(sim.run(0.1))
    for ev in events:
        ahead = ev.scan.ranges[np.argmin(np.abs(ev.scan.angles))]
        assert ahead == pytest.approx(2.0 - 0.2, abs=1e-3)  # centre distance minus radius


def test_a_robot_driven_into_a_wall_stops_there():
    with Simulation(square_room(), cfg(), 1, start_poses=[(2.0, 2.0, 0.0)]) as sim:
        sim.set_cmd(0, 0.5, 0.0)
        for _ in sim.run(10.0):
            pass
        r = sim.robots[0]
    wall_face = 4.0 - INNER
    assert wall_face - 0.2 - 0.02 < r.pose[0] <= wall_face - 0.2  # touching, never through
    assert r.wall_collisions == 1 and len(sim.collisions) == 1
    assert sim.collisions[0].with_robot is None


def test_robots_driving_into_each_other_stop_and_report_it():
    poses = [(1.0, 2.0, 0.0), (3.0, 2.0, math.pi)]
    with Simulation(square_room(), cfg(), 2, start_poses=poses) as sim:
        sim.set_cmd(0, 0.5, 0.0)
        sim.set_cmd(1, 0.5, 0.0)
        for _ in sim.run(5.0):
            pass
        a, b = sim.robots
    assert math.hypot(*(a.pose[:2] - b.pose[:2])) >= 0.4
    assert a.robot_collisions + b.robot_collisions >= 1


def test_velocity_commands_are_limited():
    with Simulation(square_room(), cfg(), 1, start_poses=[(1.0, 1.0, 0.0)]) as sim:
        sim.set_cmd(0, 5.0, 0.0)
        for _ in sim.run(2.0):
            pass
        assert sim.robots[0].v == pytest.approx(sim.cfg.robot.max_linear_mps)
        with pytest.raises(SimulationError):
            sim.set_cmd(0, math.nan, 0.0)


def test_noise_free_odometry_matches_the_motion():
    quiet = cfg(
        odometry_noise={
            "trans_sigma_per_sqrt_m": 0.0,
            "lateral_sigma_per_sqrt_m": 0.0,
            "rot_sigma_per_sqrt_rad": 0.0,
            "rot_sigma_per_sqrt_m": 0.0,
        }
    )
    with Simulation(square_room(), quiet, 1, start_poses=[(1.0, 1.0, 0.5)]) as sim:
        sim.set_cmd(0, 0.3, 0.4)
        ev = list(sim.run(3.0))[-1]
    x0, y0, t0 = 1.0, 1.0, 0.5
    dx, dy = ev.true_pose[0] - x0, ev.true_pose[1] - y0
    rel = (math.cos(t0) * dx + math.sin(t0) * dy, -math.sin(t0) * dx + math.cos(t0) * dy)
    assert ev.odom[:2] == pytest.approx(rel, abs=1e-9)
    assert ev.odom[2] == pytest.approx(ev.true_pose[2] - t0, abs=1e-9)


def _run(seed: int, threads: int = 0):
    with Simulation(load_world("office"), cfg(seed=seed, raycast_threads=threads), 3) as sim:
        for k in range(3):
            sim.set_cmd(k, 0.4, 0.2 * (k - 1))
        ev = list(sim.run(4.0))
    return np.concatenate([e.scan.ranges for e in ev]), np.concatenate([e.odom for e in ev])


def test_a_seed_reproduces_a_run_bit_for_bit():
    a, b, c = _run(5), _run(5), _run(6)
    assert np.array_equal(a[0], b[0], equal_nan=True) and np.array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0], equal_nan=True)


def test_ray_casting_on_several_threads_gives_the_same_scans_as_on_one():
    many, one = _run(5, threads=0), _run(5, threads=1)
    assert np.array_equal(many[0], one[0], equal_nan=True)
    assert np.isfinite(many[0]).sum() > 1000  # the rays hit walls, not only free space


@pytest.mark.parametrize("name", PROCEDURAL)
def test_procedural_worlds_are_closed_and_have_room_to_start(name):
    w = load_world(name)
    assert w.free.area > 20.0
    poses = spread_start_poses(w, 3, 0.2)
    assert len(poses) == 3
    for i, p in enumerate(poses):
        for q in poses[i + 1 :]:
            assert math.hypot(p[0] - q[0], p[1] - q[1]) >= 0.4


@pytest.mark.parametrize("world", WORLDS)
def test_data_worlds_wall_boxes_cover_every_occupied_pixel_and_no_free_one(shared_data, world):
    grid = read_map(shared_data / "worlds" / f"{world}.yaml")
    w = load_world(shared_data / "worlds" / f"{world}.yaml")
    res, (ox, oy) = grid.resolution, grid.origin
    cover = np.zeros(np.add(grid.shape, 2), dtype=np.int32)  # with the ring around the image
    for x0, y0, x1, y1 in w.boxes:
        c0, c1 = round((x0 - ox) / res) + 1, round((x1 - ox) / res) + 1
        r0, r1 = round((y0 - oy) / res) + 1, round((y1 - oy) / res) + 1
        cover[r0:r1, c0:c1] += 1
    cover = cover[1:-1, 1:-1]
    assert (cover[grid.occupied] >= 1).all()
    assert (cover[grid.free] == 0).all()
    assert (cover <= 1).all()  # boxes do not overlap
    assert len(w.boxes) < grid.occupied.sum() / 5  # neighbouring pixels merged


@pytest.mark.parametrize("world", ["nav2-warehouse", "nav2-depot"])
def test_a_map_whose_free_space_reaches_the_image_edge_is_closed_there(shared_data, world):
    grid = read_map(shared_data / "worlds" / f"{world}.yaml")
    w = load_world(shared_data / "worlds" / f"{world}.yaml")
    assert grid.free[[0, -1]].any() or grid.free[:, [0, -1]].any()  # the case in point
    around = shapely.box(*w.free.bounds).buffer(1.0)
    open_space = shapely.difference(around, w.walls)
    start = shapely.Point(w.start)
    inside = next(p for p in getattr(open_space, "geoms", [open_space]) if p.intersects(start))
    assert not inside.intersects(around.exterior)  # walled in: no way off the map
    assert inside.area == pytest.approx(w.free.area, rel=0.01)


def test_the_start_must_be_free():
    with pytest.raises(SimulationError):
        Simulation(square_room(), cfg(), 1, start_poses=[(0.05, 2.0, 0.0)])


def test_coverage_route_never_crosses_a_wall_thinner_than_its_grid():
    """A 50 m x 40 m world (planned on the coarse 0.25 m grid) split by a 0.1 m wall
    with a 2 m door: cell centres fall on both sides of the wall, but the route must go
    through the door (it once went through such walls, and the robot stuck there)."""
    from sim.route import COARSE_GRID_M, coverage_route

    lines = [square(0, 0, 50, 40), [(25.0, 0.0), (25.0, 18.0)], [(25.0, 20.0), (25.0, 40.0)]]
    walls = walls_from_lines(lines, 0.1)
    world = world_from_walls("split", walls, (5.0, 5.0))
    assert world.free.area > 1500 and COARSE_GRID_M > 0.1  # the coarse grid is used
    route = coverage_route(world)
    assert route[:, 0].max() > 40  # it does cover the far room...
    line = shapely.LineString(route)
    assert not line.intersects(walls)  # ...through the door, not the wall
    through = line.intersection(shapely.box(24.9, 0, 25.1, 40))
    assert through.bounds[1] > 18.0 and through.bounds[3] < 20.0


def test_the_furnished_world_is_seeded_and_cluttered():
    a, b, c = (load_world("furnished", seed=s) for s in (0, 0, 1))
    assert a.walls.equals(b.walls) and not a.walls.equals(c.walls)
    parts = shapely.get_parts(a.walls)
    legs = [p for p in parts if p.area < 0.01]  # desk and chair legs, columns
    assert len(legs) >= 40
    assert 300 < a.free_area < 380  # 24 m x 16 m less walls and furniture


def test_more_rays_in_one_step_than_pybullet_casts_in_one_batch():
    # 25 robots x 720 beams = 18,000 rays (pybullet's batch limit is 16,384): each robot
    # still sees the analytic walls of a 24 m x 24 m room (robots 2 m apart, noise off)
    world = world_from_walls("big", walls_from_lines([square(0, 0, 24, 24)], 0.2), (2.0, 2.0))
    poses = [(2.0 + 4.0 * (k % 5), 2.0 + 4.0 * (k // 5), 0.0) for k in range(25)]
    with Simulation(world, cfg(lidar={"noise_sigma_m": 0.0}), 25, start_poses=poses) as sim:
        scans = sim.scan()
    assert len(scans) == 25
    last = scans[-1].scan  # robot 24, at (18, 18): its wall at x = 23.9 straight ahead
    ahead = np.argmin(np.abs(last.angles))
    assert last.ranges[ahead] == pytest.approx(23.9 - 18.0, abs=1e-4)  # float32 in pybullet
