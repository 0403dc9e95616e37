"""The exploration reference is scored on the same truth as our runs: the free space a
robot can reach, less the same band along the walls."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import shapely

from polyswarm.benchmarks.reference import RASTER_M, _erode_truth, raster_m
from polyswarm.evaluation.coverage import reachable_free


@pytest.mark.parametrize("tolerance_m", [0.02, 0.03, 0.05, 0.08, 0.1])
def test_the_raster_holds_the_band_in_whole_cells_no_coarser_than_a_map_servers(tolerance_m):
    res = raster_m(tolerance_m)
    assert res <= RASTER_M + 1e-12
    assert abs(tolerance_m / res - round(tolerance_m / res)) < 1e-9


@pytest.mark.parametrize("tolerance_m", [0.02, 0.04, 0.1])
def test_a_square_room_loses_the_same_band_on_both_sides(tolerance_m):
    """A 2 m square room: our truth is the polygon shrunk by the band; the reference's,
    its cells at ``raster_m`` less those within the band. Both are (2 - 2 band)^2."""
    res = raster_m(tolerance_m)
    n = round(2.0 / res)
    ref = SimpleNamespace(gt=np.pad(np.ones((n, n), bool), 1), res=res, n_gt=n * n)
    band = _erode_truth(ref, tolerance_m)
    room = shapely.box(0.0, 0.0, 2.0, 2.0)
    ours = reachable_free(room, 1e-4, [(1.0, 1.0)], tolerance_m)  # a point robot: no corners
    expected = (2.0 - 2.0 * tolerance_m) ** 2
    assert band == pytest.approx(tolerance_m)
    assert ref.n_gt * res**2 == pytest.approx(expected, rel=1e-9)
    assert ours.area == pytest.approx(expected, rel=1e-3)  # one row of cells is 1 %


def test_at_a_coarse_map_servers_pixel_the_band_is_its_nearest_whole_number_of_cells():
    ref = SimpleNamespace(gt=np.pad(np.ones((40, 40), bool), 1), res=0.05, n_gt=1600)
    assert _erode_truth(ref, 0.06) == pytest.approx(0.05)  # one pixel
    assert ref.n_gt == 38 * 38
