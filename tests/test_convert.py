"""Occupancy grid <-> PolyMap (Algorithm 1), map_server files, and round trips."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from polyswarm.data import WORLDS
from polyswarm.errors import DataFormatError
from polyswarm.grids.convert import (
    grid_to_polygons,
    grid_to_polymap,
    polymap_to_grid,
    round_trip_retention,
)
from polyswarm.grids.occupancy import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from polyswarm.io.mapserver import read_map, write_map
from polyswarm.polymap import VectorType

U, Fr, Oc = UNKNOWN, FREE, OCCUPIED


def grid(rows, res=1.0, origin=(0.0, 0.0)) -> OccupancyGrid:
    # rows are given top-down (as drawn), stored bottom-up
    return OccupancyGrid(np.array(rows[::-1], dtype=np.int8), res, origin)


def lengths(polys, kind):
    total = 0.0
    for p in polys:
        for r in p.rings():
            a, b = r.segments()
            m = r.types == kind
            total += float(np.hypot(*(b - a)[m].T).sum())
    return total


def test_walled_room_with_an_open_side():
    g = grid(
        [
            [Oc, Oc, Oc, Oc],
            [Oc, Fr, Fr, U],
            [Oc, Fr, Fr, U],
            [Oc, Oc, Oc, Oc],
        ]
    )
    polys = grid_to_polygons(g)
    assert len(polys) == 1
    p = polys[0]
    assert len(p.shell) == 4  # collinear unit vectors merged into 4
    assert shapely.Polygon(p.shell.xy).equals(shapely.box(1, 1, 3, 3))
    assert lengths(polys, VectorType.OBSTACLE) == 6.0
    assert lengths(polys, VectorType.FRONTIER) == 2.0


def test_free_cells_touching_at_a_corner_stay_separate_and_valid():
    g = grid([[Fr, Oc], [Oc, Fr]])
    polys = grid_to_polygons(g)
    assert len(polys) == 2
    for p in polys:
        p.validate()


def test_obstacles_touching_at_a_corner_give_valid_holes():
    g = grid(
        [
            [Oc, Oc, Oc, Oc, Oc],
            [Oc, Fr, Fr, Fr, Oc],
            [Oc, Fr, Oc, Fr, Oc],
            [Oc, Fr, Fr, Oc, Oc],
            [Oc, Oc, Oc, Oc, Oc],
        ]
    )
    polys = grid_to_polygons(g)
    for p in polys:
        p.validate()
    pmap = grid_to_polymap(g, 2.0)
    assert pmap.explored_area() == pytest.approx(7.0)


def test_staircase_becomes_a_diagonal():
    n = 12
    rows = [[Fr if c <= r else Oc for c in range(n)] for r in range(n)]  # a 45 degree wall
    g = OccupancyGrid(np.array(rows, dtype=np.int8), 0.05)
    with_diag = grid_to_polygons(g, diagonal_tolerance_px=0.25)
    without = grid_to_polygons(g, diagonal_tolerance_px=0.0)
    nv = lambda ps: sum(len(r) for p in ps for r in p.rings())  # noqa: E731
    assert nv(with_diag) < nv(without) / 3
    # and rasterising it back gives the same free cells
    pmap = grid_to_polymap(g, 2.0)
    back = polymap_to_grid(pmap, 0.05, like=g)
    free_kept, _ = round_trip_retention(g, back)
    assert free_kept == 1.0


def test_isolated_free_specks_are_dropped():
    g = grid([[U, U, U], [U, Fr, U], [U, U, U]])
    assert grid_to_polygons(g) == []


def test_map_server_round_trip(tmp_path):
    g = grid([[Oc, Oc, Oc], [Oc, Fr, U], [Oc, Fr, Fr]], res=0.05, origin=(-1.0, 2.0))
    write_map(g, tmp_path / "m.yaml")
    back = read_map(tmp_path / "m.yaml")
    assert np.array_equal(back.data, g.data)
    assert back.resolution == 0.05 and back.origin == (-1.0, 2.0)


def test_bad_map_files_raise_data_format_error(tmp_path):
    (tmp_path / "a.yaml").write_text("image: nope.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(DataFormatError, match="cannot read image"):
        read_map(tmp_path / "a.yaml")
    (tmp_path / "b.yaml").write_text("resolution: 0.05\n")
    with pytest.raises(DataFormatError, match="missing key"):
        read_map(tmp_path / "b.yaml")
    (tmp_path / "c.yaml").write_text("image: x.pgm\nresolution: 0.05\norigin: [0, 0, 0.5]\n")
    with pytest.raises(DataFormatError, match="yaw"):
        read_map(tmp_path / "c.yaml")


@pytest.mark.parametrize("world", WORLDS)
def test_round_trip_of_the_thesis_worlds(shared_data, world):
    """Needs ../shared/data (fails without it). Walls in these maps are 1-3 pixels
    of 0.2 m; a PolyMap stores no wall thickness, so rasterising fills 0.4 m (two source
    pixels) behind obstacle vectors."""
    g = read_map(shared_data / "worlds" / f"{world}.yaml")
    pmap = grid_to_polymap(g, 2.0)
    back = polymap_to_grid(pmap, g.resolution, like=g, wall_thickness_m=2 * g.resolution)
    free_kept, occ_kept = round_trip_retention(g, back)
    assert free_kept >= 0.995
    assert occ_kept >= 0.99
