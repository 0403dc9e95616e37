"""Convex partition of cells: convex pieces, exact area, symmetric bookkeeping."""

import numpy as np
import pytest

from polyswarm.polymap import Cell, GridPolyMap, Ring, TypedPolygon, VectorType
from polyswarm.polymap.partition import partition_of
from tests.conftest import O, rect


def convex(xy: np.ndarray) -> bool:
    a, b, c = xy, np.roll(xy, -1, 0), np.roll(xy, -2, 0)
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - b[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - b[:, 0])
    return bool((cross >= -1e-12).all())


def check(pmap: GridPolyMap) -> None:
    for cell in pmap.cells.values():
        part = partition_of(cell)
        assert sum(p.area for p in part.pieces) == pytest.approx(cell.area, abs=1e-9)
        for k, p in enumerate(part.pieces):
            assert convex(p.xy)
            for i in np.nonzero(p.links >= 0)[0]:
                other = part.pieces[p.links[i]]
                assert p.types[i] == VectorType.SECTOR
                assert k in other.links.tolist()  # the split is known from both sides


def test_l_shaped_room_splits_into_convex_pieces():
    ring = Ring([(0.1, 0.1), (1.9, 0.1), (1.9, 0.8), (0.8, 0.8), (0.8, 1.9), (0.1, 1.9)], [O] * 6)
    pmap = GridPolyMap(2.0).merge(TypedPolygon(ring)).map
    part = partition_of(pmap.cells[(0, 0)])
    assert len(part.pieces) == 2
    check(pmap)
    assert len(part.internal_links()) == 1
    _, _, s, e = part.internal_links()[0]
    # the split starts at the reflex corner (0.8, 0.8)
    assert np.allclose(s, (0.8, 0.8)) or np.allclose(e, (0.8, 0.8))


def test_room_with_a_pillar():
    outer = Ring([(0.1, 0.1), (1.9, 0.1), (1.9, 1.9), (0.1, 1.9)], [O] * 4)
    hole = Ring([(0.9, 0.9), (0.9, 1.1), (1.1, 1.1), (1.1, 0.9)], [O] * 4)
    pmap = GridPolyMap(2.0).merge(TypedPolygon(outer, (hole,))).map
    check(pmap)
    part = partition_of(pmap.cells[(0, 0)])
    assert part.locate(1.0, 1.0) is None  # inside the pillar
    assert part.locate(0.5, 0.5) is not None


def random_map(rng: np.random.Generator, polygons: int, vertices: int) -> GridPolyMap:
    """Star-shaped random polygons (random vector types) merged around the origin."""
    pmap = GridPolyMap(2.0)
    for _ in range(polygons):
        c = rng.uniform(-3, 3, 2)
        a = np.sort(rng.uniform(0, 2 * np.pi, vertices))
        r = rng.uniform(0.5, 3.0, vertices)
        xy = c + np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
        pmap = pmap.merge(TypedPolygon(Ring(xy, rng.integers(0, 2, vertices)))).map
    return pmap


def test_random_cells_partition_exactly():
    check(random_map(np.random.default_rng(3), 20, 30))


def test_locate_on_a_shared_split_finds_a_piece():
    pmap = GridPolyMap(2.0).merge(rect(0.5, 0.5, 3.5, 1.5)).map
    # x = 2.0 is the cell border: either cell may answer, but one must
    assert pmap.locate(2.0, 1.0) is not None


def test_locate_many_answers_as_locate_does_point_by_point():
    # random cells (pieces, holes, shared splits) and points inside, outside, on
    # vectors and on cell borders: the batched lookup is the one-point lookup
    rng = np.random.default_rng(7)
    pmap = random_map(rng, 12, 24)
    pts = [rng.uniform(-6, 6, (400, 2)), np.array([[0.0, 0.0], [2.0, 1.0], [-2.0, -2.0]])]
    for cell in pmap.cells.values():  # points on the pieces' own vertices and edges
        for p in partition_of(cell).pieces:
            pts.append(p.xy)
            pts.append(0.5 * (p.xy + np.roll(p.xy, -1, axis=0)))
    pts = np.concatenate(pts)
    assert pmap.locate_many(pts) == [pmap.locate(x, y) for x, y in pts]
    assert pmap.locate_many(np.zeros((0, 2))) == []


def test_a_collinear_vertex_the_triangulation_skips_keeps_its_types():
    # cell (0, 0) of an in-process run on the rooms world (1 robot, seed 2): a 1 mm
    # frontier vector on the east border, then the border's sector vector, collinear.
    # The triangulation left out the zero-area triangle there, so one piece's edge ran
    # along both; it was typed frontier, the cell had no opening to its neighbours, and
    # the robot standing in it could reach nothing (the mission ended at 43 %)
    F, S = VectorType.FRONTIER, VectorType.SECTOR
    shell = Ring(
        [
            (0.099, 0.097),
            (0.88671, 0.09962),
            (0.886, 0.098),
            (2.0, 0.09818),
            (2.0, 0.09911),
            (2.0, 2.0),
            (0.09958, 2.0),
            (0.099, 2.0),
        ],
        [O, F, O, F, S, S, F, O],
    )
    hole = Ring(
        [(1.49847, 1.49847), (1.49884, 1.49909), (1.49919, 1.49936), (1.4992, 1.49936)],
        [F] * 4,
    )
    cell = Cell((0, 0), 2.0, (TypedPolygon(shell, (hole,)),))
    pieces = partition_of(cell).pieces
    assert sum(p.area for p in pieces) == pytest.approx(cell.area, abs=1e-9)
    # the east (x = 2) and north (y = 2) borders: sector along their whole length
    # but the mapped millimetre of frontier
    for axis in (0, 1):
        length = {F: 0.0, S: 0.0}
        for p in pieces:
            nxt = np.roll(p.xy, -1, axis=0)
            on = (np.abs(p.xy[:, axis] - 2.0) < 1e-9) & (np.abs(nxt[:, axis] - 2.0) < 1e-9)
            for k in np.nonzero(on)[0]:
                length[VectorType(p.types[k])] += float(np.hypot(*(nxt[k] - p.xy[k])))
        assert length[S] == pytest.approx(2.0 - (0.09911 if axis == 0 else 0.09958), abs=1e-9)
        assert length[F] == pytest.approx(0.00093 if axis == 0 else 0.09958 - 0.099, abs=1e-9)
