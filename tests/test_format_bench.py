"""The map built from noisy scans along a route (polyswarm/benchmarks/format.py): the
PolyMap and the 5 cm grid of the same scans describe the same room."""

from __future__ import annotations

from polyswarm.benchmarks.format import GRID_RESOLUTION_M, route_maps
from polyswarm.grids.occupancy import FREE, OCCUPIED
from polyswarm.polymap import GridPolyMap, Ring, TypedPolygon
from tests.conftest import O


def test_the_polymap_and_the_grid_of_one_route_cover_the_same_room():
    room = GridPolyMap(2.0).merge(TypedPolygon(Ring([(0, 0), (6, 0), (6, 4), (0, 4)], [O] * 4)))
    pmap, grid = route_maps(room.map, (-1.0, -1.0, 7.0, 5.0), n=15)
    t = grid.trinary()
    free_grid = (t == FREE).sum() * GRID_RESOLUTION_M**2
    # the lidar sees most of the 24 m2 room from its walk; both maps agree on how much
    assert 15.0 < pmap.explored_area() <= 24.0 + 0.5
    assert abs(free_grid - pmap.explored_area()) < 0.1 * pmap.explored_area()
    # walls: occupied cells lie on the room's outline, none inside it
    rows, cols = (t == OCCUPIED).nonzero()
    x = grid.origin[0] + (cols + 0.5) * GRID_RESOLUTION_M
    y = grid.origin[1] + (rows + 0.5) * GRID_RESOLUTION_M
    inside = (x > 0.15) & (x < 5.85) & (y > 0.15) & (y < 3.85)
    assert len(x) > 100 and not inside.any()
