"""The simulated lidar fails as real low-cost ones do: by range, incidence and surface, in
runs, with mixed pixels at edges; dark and glass stretches in the worlds."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from polyswarm.config import Config, LidarConfig, with_overrides
from sim import Simulation, load_world
from sim.lidar import BeamsSeen, dropout_probability, measure
from sim.shapes import dark_surfaces, square, walls_from_lines, world_from_walls


def lidar(**over) -> LidarConfig:
    return with_overrides(Config(), {"sim": {"lidar": over}}).sim.lidar


def seen(r, incidence_deg=0.0, dark=False, n=1) -> BeamsSeen:
    return BeamsSeen(
        np.full(n, float(r)), np.full(n, math.radians(incidence_deg)), np.full(n, dark)
    )


def test_dropout_probability_by_range_incidence_and_surface_by_hand():
    cfg = lidar(
        range_max_m=10.0,
        dropout_prob=0.1,
        dropout_far_prob=0.9,
        dropout_far_from=0.5,
        dropout_grazing_prob=0.5,
        dark_dropout_prob=0.95,
    )
    assert dropout_probability(seen(1.0), cfg)[0] == pytest.approx(0.1, abs=2e-3)
    assert dropout_probability(seen(5.0), cfg)[0] == pytest.approx(0.5)  # the step's middle
    assert dropout_probability(seen(9.9), cfg)[0] == pytest.approx(0.9, abs=2e-3)
    # head-on to 45 degrees adds nothing; at 80 degrees and beyond, all of the grazing share
    assert dropout_probability(seen(1.0, 45.0), cfg)[0] == pytest.approx(0.1, abs=2e-3)
    assert dropout_probability(seen(1.0, 85.0), cfg)[0] == pytest.approx(1 - 0.9 * 0.5, abs=2e-3)
    assert dropout_probability(seen(1.0, 0.0, dark=True), cfg)[0] == pytest.approx(0.95)


def test_dropouts_come_in_runs_when_the_model_says_so():
    def runs(run_beams: float) -> float:
        cfg = lidar(range_max_m=10.0, dropout_prob=0.5, dropout_run_beams=run_beams)
        rng = np.random.default_rng(0)
        out = []
        for _ in range(50):
            bad = np.isinf(measure(seen(2.0, n=720), cfg, rng))
            edges = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
            out += (np.nonzero(edges == -1)[0] - np.nonzero(edges == 1)[0]).tolist()
        return float(np.mean(out))

    independent, correlated = runs(1.0), runs(10.0)
    assert independent == pytest.approx(2.0, rel=0.1)  # p = 0.5: runs of two on average
    assert correlated > 3 * independent


def test_a_beam_at_an_edge_may_fall_between_the_two_surfaces():
    cfg = lidar(range_max_m=10.0, noise_sigma_m=0.0, mixed_pixel_prob=1.0, fov_rad=math.pi)
    true = np.array([2.0] * 10 + [5.0] * 10)
    r = measure(BeamsSeen.plain(true), cfg, np.random.default_rng(1))
    assert np.allclose(r[:9], 2.0) and np.allclose(r[11:], 5.0)  # away from the edge
    assert all(2.0 < x < 5.0 for x in r[9:11])  # the two beams at it: between


def test_dark_stretches_cover_about_their_share_of_the_walls_and_are_seeded():
    world = load_world("office")
    outline = sum(r.length for r in shapely.get_rings(shapely.get_parts(world.walls)))
    dark = dark_surfaces(world, 0.1, seed=3)
    assert dark_surfaces(world, 0.1, seed=3).equals(dark)
    assert not dark_surfaces(world, 0.1, seed=4).equals(dark)
    band = 2 * 0.05  # a thin band along each stretch
    assert 0.05 < dark.area / band / outline < 0.16
    assert dark_surfaces(world, 0.0, seed=3).is_empty


def test_a_room_of_black_walls_returns_nothing_to_a_lidar_that_cannot_see_black():
    world = world_from_walls("black", walls_from_lines([square(0, 0, 4, 4)], 0.2), (2.0, 2.0))
    over = {"dark_surface_share": 1.0, "lidar": {"dark_dropout_prob": 1.0}}
    sim_cfg = with_overrides(Config(), {"sim": over}).sim
    with Simulation(world, sim_cfg, 1, start_poses=[(2.0, 2.0, 0.0)]) as sim:
        assert np.isinf(sim.scan()[0].scan.ranges).all()
    sim_cfg = with_overrides(Config(), {"sim": {**over, "dark_surface_share": 0.0}}).sim
    with Simulation(world, sim_cfg, 1, start_poses=[(2.0, 2.0, 0.0)]) as sim:
        assert np.isfinite(sim.scan()[0].scan.ranges).all()


def test_walls_met_at_a_grazing_angle_return_less_than_walls_met_head_on():
    world = world_from_walls("hall", walls_from_lines([square(0, 0, 8, 2)], 0.2), (1.0, 1.0))
    over = {"dark_surface_share": 0.0, "lidar": {"dropout_grazing_prob": 1.0}}
    sim_cfg = with_overrides(Config(), {"sim": over}).sim
    with Simulation(world, sim_cfg, 1, start_poses=[(1.0, 1.0, 0.0)]) as sim:
        scan = sim.scan()[0].scan
    a = np.abs(np.arctan2(np.sin(scan.angles), np.cos(scan.angles)))
    side = np.abs(a - math.pi / 2) < math.radians(30)  # at the long walls, within 30 deg
    assert np.isfinite(scan.ranges[side]).all()
    # beams 8-10 degrees right of the hall's axis meet a long wall 0.9 m off at 80-82
    # degrees from its normal, 5.2-6.5 m away (closer to the axis they reach the end wall
    # 6.9 m away, met head-on; to the left the short wall 1 m away)
    graze = np.abs(a - math.radians(9.0)) < math.radians(1.0)
    assert np.isinf(scan.ranges[graze]).mean() > 0.8


@pytest.mark.parametrize("profile", ["neato", "hokuyo", "turtlebot4"])
def test_the_fitted_profiles_lose_what_their_real_lidars_lose_indoors(profile):
    from polyswarm.benchmarks.lidarfit import simulated

    share = simulated(profile, "office", poses=20)["no_return_share"]
    # neato: 72 and 82 % in the two real recordings; an RPLIDAR 31 % (issue 65); the
    # URG-04LX in its corridor 20 %, more in the office's larger rooms at 5.6 m
    lo, hi = {"neato": (0.65, 0.9), "turtlebot4": (0.2, 0.4), "hokuyo": (0.2, 0.7)}[profile]
    assert lo < share < hi
