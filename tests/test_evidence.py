"""The evidence behind a map: counts you can work out by hand, views of them, counts that
follow the pose graph, and keyframes of a lidar that loses most of its beams."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from polyswarm.config import Config, with_overrides
from polyswarm.polymap import VectorType
from polyswarm.raycast import cast_rays
from polyswarm.slam.evidence import HIT, MISS, WEAK_MISS, EvidenceGrid, KeyframeRays, Rays
from polyswarm.slam.polyslam import PolySlam
from polyswarm.slam.scan import LaserScan, ScanPoints


def rays(origin, ends, hit) -> Rays:
    ends = np.asarray(ends, dtype=float).reshape(-1, 2)
    return Rays(np.tile(np.asarray(origin, dtype=float), (len(ends), 1)), ends, np.asarray(hit))


def cell(ev: EvidenceGrid, x: float, y: float) -> np.ndarray:
    """(hits, misses, weak misses) of the cell holding (x, y)."""
    return ev.counts[:, *_rc(ev, x, y)]


def test_a_return_misses_every_cell_it_crossed_and_hits_its_end():
    ev = EvidenceGrid(0.05)
    ev.add(rays((0.01, 0.01), [(1.01, 0.01)], [True]))
    for x in np.arange(0.01, 1.0, 0.05):
        assert tuple(cell(ev, x, 0.01)) == (0, 1, 0), x
    assert tuple(cell(ev, 1.01, 0.01)) == (1, 0, 0)
    assert tuple(cell(ev, 1.06, 0.01)) == (0, 0, 0)  # beyond the return: nothing known
    free, occ = ev.masks()
    assert free.sum() == 20 and occ.sum() == 1


def test_one_hit_outvotes_the_weak_evidence_of_a_beam_without_a_return():
    ev = EvidenceGrid(0.05)
    ev.add(rays((0.01, 0.01), [(2.01, 0.01)], [False]))  # no return, trusted to 2 m
    assert tuple(cell(ev, 1.51, 0.01)) == (0, 0, 1)
    free, _ = ev.masks()
    assert free.sum() == 41  # weak evidence is still free space
    ev.add(rays((0.01, 1.01), [(1.51, 0.01)], [True]))  # another scan: a wall at 1.5 m
    assert HIT + WEAK_MISS > 0 > MISS
    _, occ = ev.masks()
    assert occ[*_rc(ev, 1.51, 0.01)]


def _rc(ev, x, y):
    """The array row and column of the cell holding (x, y)."""
    return (math.floor(y / ev.res) - int(ev.first[1]), math.floor(x / ev.res) - int(ev.first[0]))


@settings(max_examples=40, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(-5, 5), st.floats(-5, 5), st.floats(-5, 5), st.floats(-5, 5), st.booleans()
        ),
        min_size=1,
        max_size=30,
    )
)
def test_counting_a_scan_out_again_leaves_nothing(beams):
    ev = EvidenceGrid(0.1)
    scans = [Rays(np.array([b[:2]]), np.array([b[2:4]]), np.array([b[4]])) for b in beams]
    ev.add(scans)
    assert ev.counts.any()
    ev.add(scans, -1)
    assert not ev.counts.any()


def _room_points(pose, keep=None) -> ScanPoints:
    """A 360-beam scan from ``pose`` in the room [0, 6] x [0, 4] (robot frame points);
    ``keep``: which beams returned."""
    walls = np.array([[0, 0, 6, 0], [6, 0, 6, 4], [6, 4, 0, 4], [0, 4, 0, 0]], dtype=float)
    a = -math.pi + np.arange(360) * (2 * math.pi / 360)
    r = cast_rays(pose[:2], a + pose[2], walls[:, :2], walls[:, 2:], 10.0)
    xy = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
    valid = np.ones(360, dtype=bool) if keep is None else keep
    return ScanPoints(xy, valid, True, np.zeros(2), ~valid)


def test_a_keyframe_moved_by_the_graph_counts_as_if_it_had_been_there():
    a, b = KeyframeRays(EvidenceGrid(0.05)), KeyframeRays(EvidenceGrid(0.05))
    pts = _room_points((2.0, 2.0, 0.0))
    a.add(0, (2.0, 2.0, 0.0), np.zeros(3), pts)
    a.add(0, (2.0, 2.0, 0.0), np.array([0.3, 0.0, 0.1]), pts)  # a sweep after it
    assert a.move_to([np.array([2.5, 1.5, 0.2])]) == 1
    b.add(0, (2.5, 1.5, 0.2), np.zeros(3), pts)
    b.add(0, (2.5, 1.5, 0.2), np.array([0.3, 0.0, 0.1]), pts)
    assert _cells(a.grid) == _cells(b.grid)
    assert a.move_to([np.array([2.51, 1.5, 0.2])]) == 0  # a nudge below half a cell


def _cells(ev: EvidenceGrid) -> dict:
    """Every counted cell by its world index (i, j): its counts."""
    r, c = np.nonzero(ev.counts.any(axis=0))
    j0, i0 = (int(v) for v in ev.first)
    return {
        (j0 + int(cc), i0 + int(rr)): tuple(ev.counts[:, rr, cc])
        for rr, cc in zip(r, c, strict=True)
    }


def test_the_view_from_the_middle_of_a_room_ends_on_its_walls():
    ev = EvidenceGrid(0.05)
    kr = KeyframeRays(ev)
    kr.add(0, (3.0, 2.0, 0.0), np.zeros(3), _room_points((3.0, 2.0, 0.0)))
    reach, on = ev.view(np.array([3.0, 2.0]), np.array([0.0, math.pi / 2, math.pi]), 10.0)
    assert reach == pytest.approx([3.0, 2.0, 3.0], abs=0.06)
    assert on.all()
    reach, on = ev.view(np.array([3.0, 2.0]), np.array([0.0]), 2.0)  # short of the wall
    assert not on[0]


def _dropout_room(slam_cfg, seed: int, returns: float):
    """PolySLAM on a robot turning in place in the room with a lidar that loses beams in
    runs (about ``1 - returns`` of them); the share of the room's wall length within
    0.1 m of an obstacle vector."""
    rng = np.random.default_rng(seed)
    slam = PolySlam(slam_cfg, 2.0, (3.0, 2.0, 0.0), out_of_range="zero")
    for k in range(40):
        th = 0.15 * k
        pose = (3.0 + 0.01 * k, 2.0, th)
        pts = _room_points(pose)
        r = np.hypot(*pts.xy.T)
        keep = np.repeat(rng.random(36) < returns, 10)  # runs of 10 beams: dark stretches
        ranges = np.where(keep, r, 0.0)
        scan = LaserScan(ranges, -math.pi, 2 * math.pi / 360, 0.05, 10.0)
        slam.process(scan, pose)
    s, e, _ = slam.map.vectors([VectorType.OBSTACLE])
    wall = np.array(
        [[x, 0.0] for x in np.arange(0.05, 6, 0.1)] + [[6.0, y] for y in np.arange(0.05, 4, 0.1)]
    )
    from polyswarm.polymap import point_segment_distance

    d = np.array([point_segment_distance(p, s, e).min() if len(s) else np.inf for p in wall])
    return float((d <= 0.1).mean())


def test_sparse_returns_seen_by_many_sweeps_make_walls_not_frontiers():
    base = Config().slam
    on = with_overrides(
        Config(), {"slam": {"evidence": {"enabled": True}, "no_return_free_m": 1.0}}
    ).slam
    without = np.mean([_dropout_room(base, s, 0.3) for s in range(3)])
    with_evidence = np.mean([_dropout_room(on, s, 0.3) for s in range(3)])
    assert with_evidence >= 0.9 > without


def test_a_cell_knows_where_its_returns_fell_inside_it():
    ev = EvidenceGrid(0.05)
    ev.add(rays((0.01, 0.01), [(1.012, 0.01)], [True]))  # two scans, one cell
    ev.add(rays((0.01, 0.01), [(1.018, 0.02)], [True]))
    occ, pts = ev.hit_centroids((0, ev.shape[0], 0, ev.shape[1]))
    assert occ.sum() == 1
    assert np.allclose(pts[0], (1.015, 0.015), atol=1e-5)
    ev.add(rays((0.01, 0.01), [(1.012, 0.01)], [True]), -1)  # counted out again
    _, pts = ev.hit_centroids((0, ev.shape[0], 0, ev.shape[1]))
    assert np.allclose(pts[0], (1.018, 0.02), atol=1e-5)


@pytest.mark.parametrize("offset", [(0.08, -0.05, 0.03), (-0.1, 0.06, -0.04)])
def test_a_scan_placed_off_is_brought_back_onto_the_walls_it_saw_before(offset):
    """The room [0, 6] x [0, 4] seen from two poses; a third scan placed 8-12 cm and 2
    degrees off is moved back to where it was taken, to a centimetre."""
    from polyswarm.slam import gridmatch

    grid = KeyframeRays(EvidenceGrid(0.05))
    for i, pose in enumerate([(2.0, 2.0, 0.0), (4.0, 1.5, 0.5)]):
        grid.add(i, pose, np.zeros(3), _room_points(pose))
    truth = np.array([3.0, 2.5, 0.2])
    pts = _room_points(truth).xy
    out = gridmatch.refine(grid.grid, pts, truth + offset, radius_m=8.0)
    assert out is not None
    pose, share, before = out
    assert np.hypot(*(pose[:2] - truth[:2])) < 0.01
    assert abs(pose[2] - truth[2]) < math.radians(0.3)
    assert share > 0.95 > before


def test_returns_far_from_every_wall_leave_nothing_to_refine():
    from polyswarm.slam import gridmatch

    grid = KeyframeRays(EvidenceGrid(0.05))
    grid.add(0, (2.0, 2.0, 0.0), np.zeros(3), _room_points((2.0, 2.0, 0.0)))
    far = np.random.default_rng(0).uniform(20, 30, (50, 2))  # another building
    assert gridmatch.refine(grid.grid, far, np.zeros(3), radius_m=5.0) is None
