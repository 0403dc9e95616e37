"""The bandwidth baselines (polyswarm/gridmap.py, polyswarm/benchmarks/bandwidth.py) on
scans whose cells and bytes can be checked by hand."""

from __future__ import annotations

import numpy as np
import pytest

from polyswarm.benchmarks import bandwidth as bw
from polyswarm.grids.counting import CountingGrid
from polyswarm.grids.occupancy import FREE, OCCUPIED, UNKNOWN
from polyswarm.slam.scan import LaserScan

RES = 0.05


def beam(r: float, angle: float = 0.0) -> LaserScan:
    """One beam of range ``r`` (inf: no return) at ``angle``."""
    return LaserScan(np.array([r]), angle, 0.01, 0.05, 10.0)


def cell_of(g: CountingGrid, x: float, y: float) -> tuple[int, int]:
    return int((y - g.origin[1]) / RES), int((x - g.origin[0]) / RES)


def test_one_beam_frees_the_cells_it_passes_and_occupies_its_end():
    g = CountingGrid((-1.0, -1.0, 2.0, 1.0), RES)
    g.integrate(beam(1.0), (0.0125, 0.0125, 0.0))  # from inside cell (0, 0) along +x
    t = g.trinary()
    row = t[cell_of(g, 0.0125, 0.0125)[0]]
    c0 = cell_of(g, 0.0125, 0.0125)[1]
    # cells 0..18 along the beam are free after one pass (gmapping: 0 hits of 1 visit),
    # the end cell at x = 1.0125 m is occupied, nothing beyond it is known
    assert (row[c0 : c0 + 20] == FREE).all()
    assert row[c0 + 20] == OCCUPIED
    assert (row[c0 + 21 :] == UNKNOWN).all()
    assert (t == FREE).sum() == 20 and (t == OCCUPIED).sum() == 1


def test_a_cell_is_occupied_while_its_hits_are_more_than_a_quarter_of_its_visits():
    g = CountingGrid((-1.0, -1.0, 2.0, 1.0), RES)
    pose = (0.0125, 0.0125, 0.0)
    g.integrate(beam(0.5), pose)  # hit once: 1 of 1
    end = cell_of(g, 0.5125, 0.0125)
    assert g.trinary()[end] == OCCUPIED
    for passes, expected in ((1, OCCUPIED), (2, OCCUPIED), (3, FREE)):
        g.integrate(beam(1.0), pose)  # passes through the cell
        assert g.visits[end] == 1 + passes
        assert g.trinary()[end] == expected  # 1/2, 1/3: above 0.25; 1/4 is not


def test_a_beam_with_no_return_clears_the_free_range_and_occupies_nothing():
    g = CountingGrid((-1.0, -1.0, 5.0, 1.0), RES, free_range_m=2.0)
    g.integrate(beam(np.inf), (0.0125, 0.0125, 0.0))
    t = g.trinary()
    assert (t == OCCUPIED).sum() == 0
    assert (t == FREE).sum() == pytest.approx(2.0 / RES, abs=1)


def test_a_keyframe_scan_round_trips_on_the_centimetre_grid_and_compresses():
    rng = np.random.default_rng(0)
    r = 2.0 + 0.5 * np.sin(np.linspace(0, 6, 720)) + rng.normal(0, 0.01, 720)
    r[[5, 100, 101]] = np.inf
    r[200] = np.nan
    scan = LaserScan(r, -2.35, 0.0065, 0.05, 30.0)
    raw = bw.encode_keyframe_scan(scan, (1.0, -2.0, 0.5))
    back, pose, a0, da = bw.decode_keyframe_scan(raw)
    ok = np.isfinite(r)
    assert np.abs(back[ok] - r[ok]).max() <= bw.SCAN_QUANTUM_M / 2 + 1e-9
    assert (back[~ok] == 0).all()
    assert np.allclose(pose, (1.0, -2.0, 0.5), atol=1e-6)
    assert a0 == pytest.approx(-2.35, abs=1e-6) and da == pytest.approx(0.0065, abs=1e-9)
    plain = bw.SCAN_HEADER.size + 2 * len(r)
    assert len(raw) < 0.8 * plain  # smooth ranges: the differences compress


def test_measure_adds_up_every_scheme_and_picks_the_smallest_baseline():
    """Two keyframes of a robot in a corridor, with PolyMap deltas of given sizes: the
    totals are the sums of what each scheme sends, and the best baseline is the smallest."""
    rec = bw.Recording("hand", free_range_m=3.0)
    for k in range(2):
        r = np.full(90, 1.0 + 0.1 * k)
        scan = LaserScan(r, -0.78, 0.0175, 0.05, 10.0)
        rec.keyframes.append(
            bw.Keyframe("r1", float(k), scan, np.array([0.5 * k, 0.0, 0.0]), 400, 300, 900)
        )
    res = bw.measure(rec)
    c = res["cumulative_bytes"]
    assert c["polymap_delta"] == 800 and c["polymap_cells"] == 1800
    scans = sum(len(bw.encode_keyframe_scan(k.scan, k.pose)) for k in rec.keyframes)
    assert c["keyframe_scans"] == scans
    best = min(bw.BASELINE_SCHEMES, key=lambda s: c[s])
    assert res["best_baseline"] == best
    assert res["delta_bytes_ratio_vs_best_baseline"] == pytest.approx(800 / c[best])
    assert res["delta_bytes_ratio_vs_keyframe_scans"] == pytest.approx(800 / scans)
    assert res["best_grid_delta_scheme"] in bw.GRID_DELTA_SCHEMES
    # the first update carries everything seen; a zlib'd full grid is never smaller
    assert c["grid_full_zlib"] >= c["grid_update_zlib"] > 0
