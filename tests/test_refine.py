"""Polygon refinement (thesis 3.5, Algorithm 3): hand-checkable chains and properties."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given
from hypothesis import strategies as st

from polyswarm.config import RefineConfig
from polyswarm.polymap import Ring, TypedPolygon
from polyswarm.raycast import cast_rays
from polyswarm.slam.keyframe import keyframe_polygon
from polyswarm.slam.refine import fit_chain, fit_first_line, refine_polygon, refine_ring
from polyswarm.slam.scan import LaserScan, scan_to_points
from tests.conftest import F, O

CFG = RefineConfig()


def test_score_is_formula_3_9():
    # a perfect line of n points: e = 0, so s = w / c with w = (n / (n + a))^b
    pts = np.stack([np.linspace(0, 1, 11), np.zeros(11)], axis=1)
    fit = fit_first_line(pts, CFG)
    assert fit.n_vectors == 10
    assert fit.score == pytest.approx((11 / 12) ** 4 / 0.001)


def test_noisy_straight_wall_becomes_one_vector():
    rng = np.random.default_rng(1)
    x = np.linspace(0, 4, 200)
    pts = np.stack([x, rng.normal(0, 0.007, 200)], axis=1)  # 4 sigma inside 0.03 m
    segs = fit_chain(pts, CFG)
    assert len(segs) == 1 and segs[0][1] == 199
    assert abs(segs[0][2].normal[1]) > 0.999  # the line runs along x


def test_corner_splits_into_two_lines():
    a = np.stack([np.linspace(0, 2, 41), np.zeros(41)], axis=1)
    b = np.stack([np.full(40, 2.0), np.linspace(0.05, 2, 40)], axis=1)
    segs = fit_chain(np.vstack([a, b]), CFG)
    assert len(segs) == 2
    assert segs[0][1] == 40  # the first line ends exactly at the corner point


def test_ring_corner_vertex_is_the_line_intersection():
    # a noisy square room, all obstacles: refined to 4 vectors meeting at the corners
    rng = np.random.default_rng(2)
    side = np.linspace(0, 1, 50, endpoint=False)
    sq = np.concatenate(
        [
            np.stack([side * 4, 0 * side], 1),
            np.stack([4 + 0 * side, side * 3], 1),
            np.stack([4 - side * 4, 3 + 0 * side], 1),
            np.stack([0 * side, 3 - side * 3], 1),
        ]
    ) + rng.normal(0, 0.005, (200, 2))
    xy, _ = refine_ring(sq, np.zeros(200, np.uint8), CFG)
    assert len(xy) == 4
    corners = np.array([[0, 0], [4, 0], [4, 3], [0, 3]])
    for c in corners:
        assert np.hypot(*(xy - c).T).min() < 0.02


def test_flat_junction_between_types_uses_projections():
    # an obstacle chain continuing straight as a frontier chain: no unstable intersection
    pts = np.stack([np.linspace(0, 4, 41), np.zeros(41)], 1)
    ring = np.vstack([pts, [[4, 2], [0, 2]]])
    types = np.array([O] * 20 + [F] * 20 + [F, F, F], dtype=np.uint8)
    xy, t = refine_ring(ring, types, CFG)
    assert np.all(np.isfinite(xy))
    assert (t == O).sum() >= 1 and (t == F).sum() >= 1
    assert np.abs(xy[:, 1]).min() < 1e-9  # vertices stay on the wall line


def _curves_keyframe(seed: int = 0):
    from sim.world import load_world

    world = load_world("curves")
    s, e = world.wall_segments
    rng = np.random.default_rng(seed)
    pose = (3.5, 3.0, 0.3)
    fov, n = math.radians(350), 1401  # thesis 5.6: 350 degrees at 0.25 degree steps
    a = np.linspace(-fov / 2, fov / 2, n)
    r = cast_rays(pose[:2], a + pose[2], s, e, 30.0) + rng.normal(0, 0.01, n)
    pts = scan_to_points(LaserScan(r, -fov / 2, a[1] - a[0], 0.05, 30.0))
    return keyframe_polygon(pts, pose, 0.5), pts, pose


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_curves_keyframe_within_targets(seed):
    """Thesis Table 5.4 setting: at most 80 vectors, every scan point within 0.03 m.

    With sigma 0.01 m noise a few of 1401 points lie beyond 0.03 m of any fitted wall;
    fitting at 0.025 m and pinning the rest keeps every point within 0.03 m."""
    kf, _, _ = _curves_keyframe(seed)
    cfg = RefineConfig(inlier_threshold_m=0.025, max_point_error_m=0.03)
    ref, how = refine_polygon(kf, cfg)
    assert how in ("refined", "projected")
    assert len(ref.shell) <= 80
    d = shapely.distance(shapely.LinearRing(ref.shell.xy), shapely.points(kf.shell.xy))
    assert d.max() <= 0.03 + 1e-9


@given(st.integers(0, 10_000), st.floats(0.0, 0.05))
def test_refinement_always_gives_a_valid_simple_polygon(seed, noise):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(8, 200))
    a = np.sort(rng.uniform(-2.5, 2.5, n))
    r = (
        np.abs(rng.uniform(0.5, 6.0) + np.cumsum(rng.normal(0, 0.2, n)))
        + 0.3
        + rng.normal(0, noise, n)
    )
    xy = np.stack([r * np.cos(a), r * np.sin(a)], 1)
    xy = np.vstack([xy, [[0.0, 0.0]]])
    types = rng.integers(0, 2, n + 1).astype(np.uint8)
    poly = TypedPolygon(Ring(xy, types))
    try:
        poly.validate()
    except Exception:
        return  # the random star itself is degenerate
    out, _ = refine_polygon(poly, CFG)
    out.validate()
