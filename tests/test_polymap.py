"""PolyMap merge, queries and deltas on geometry checkable by hand, plus property tests."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given
from hypothesis import strategies as st

from polyswarm.errors import DeltaGapError, InvalidPolygonError, MapError
from polyswarm.polymap import (
    UNITS_PER_M,
    GridPolyMap,
    MergeOp,
    MergeOptions,
    Ring,
    TypedPolygon,
    VectorType,
    cells_digest,
    snap_polygon,
)
from polyswarm.polymap.borders import _across_changed_borders
from polyswarm.polymap.partition import partition_of
from polyswarm.polymap.vectortypes import _obstacle_mask, _segment_tree, fill_notches
from tests.conftest import F, O, assert_well_formed, rect, star, total_length

# --- merge on hand-checkable geometry ---------------------------------------------------


def test_square_across_four_cells_has_known_vectors():
    pmap = GridPolyMap(2.0).merge(rect(0.5, 0.5, 3.5, 3.5, (O, F, O, F))).map
    assert sorted(pmap.cells) == [(0, 0), (0, 1), (1, 0), (1, 1)]
    assert pmap.explored_area() == pytest.approx(9.0)
    # 3 m of obstacle at the bottom and top, 3 m of frontier left and right,
    # 4 sector borders of 1.5 m seen from both sides
    assert total_length(pmap, VectorType.OBSTACLE) == pytest.approx(6.0)
    assert total_length(pmap, VectorType.FRONTIER) == pytest.approx(6.0)
    assert total_length(pmap, VectorType.SECTOR) == pytest.approx(12.0)
    assert_well_formed(pmap)


def test_two_overlapping_squares_give_the_union_area():
    pmap = GridPolyMap(2.0)
    pmap = pmap.merge(rect(0, 0, 2, 2)).map
    pmap = pmap.merge(rect(1, 1, 3, 3)).map
    assert pmap.explored_area() == pytest.approx(7.0)
    assert_well_formed(pmap)


def test_new_explored_space_removes_a_covered_frontier():
    pmap = GridPolyMap(2.0).merge(rect(0.2, 0.2, 1.0, 1.0, (O, F, O, O))).map
    assert total_length(pmap, VectorType.FRONTIER) == pytest.approx(0.8)
    pmap = pmap.merge(rect(0.9, 0.2, 1.8, 1.0, (O, O, O, F))).map
    assert total_length(pmap, VectorType.FRONTIER) == pytest.approx(0.0)
    assert total_length(pmap, VectorType.OBSTACLE) == pytest.approx(1.6 + 1.6 + 0.8 + 0.8)


def test_cells_are_judged_one_by_one_in_a_batch():
    # the map's room reaches 3 cm into cell (1, 0) and ends there in a frontier; one
    # robot saw the room with its east wall 2 cm before that border, in cell (0, 0),
    # another saw it reach 2 cm into cell (1, 0), open to the east. Each cell alone
    # changes nothing; in one batch, cell (0, 0)'s wall, 5 cm from cell (1, 0)'s
    # frontier, must not count: it is not on a frontier of its own cell
    big = GridPolyMap(2.0).merge(rect(0.2, 0.2, 2.03, 1.8, (O, F, O, O))).map
    a = GridPolyMap(2.0).merge(rect(0.3, 0.3, 1.98, 1.7, (O, O, O, O))).map
    b = GridPolyMap(2.0).merge(rect(0.3, 0.3, 2.02, 1.7, (O, F, O, O))).map
    cells = [a.cells[(0, 0)], b.cells[(1, 0)]]
    opt = MergeOptions(obstacle_snap_m=0.08)
    assert [big._cells_that_change([c], opt) for c in cells] == [[], []]
    assert big._cells_that_change(cells, opt) == []
    # while a wall on the frontier of its own cell does count, in a batch too
    c = GridPolyMap(2.0).merge(rect(0.3, 0.3, 2.01, 1.7, (O, O, O, O))).map
    assert big._cells_that_change([*cells, c.cells[(1, 0)]], opt) == [c.cells[(1, 0)]]


def test_box_state_changes_when_a_cell_of_the_box_changes():
    pmap = GridPolyMap(2.0).merge(rect(0.2, 0.2, 3.8, 3.8, (O, F, O, O))).map
    assert pmap.box_state(0, 0, 1, 1) == (4, pmap.version)
    assert pmap.box_state(5, 5, 9, 9) == (0, -1)  # no cell there
    before = pmap.box_state(-1, -1, 1, 1)
    far = pmap.merge(rect(20.2, 0.2, 21.8, 1.8, (O, O, O, F))).map
    assert far.box_state(-1, -1, 1, 1) == before  # a change elsewhere
    near = far.merge(rect(3.5, 0.5, 5.5, 1.5, (O, O, O, O))).map
    assert near.box_state(-1, -1, 1, 1) != before  # cell (1, 0) grew
    assert near.box_state(0, 0, 2, 0)[0] == 3  # and cell (2, 0) is new


def test_obstacle_wins_over_a_coincident_frontier():
    a = GridPolyMap(2.0).merge(rect(0.2, 0.2, 1.0, 1.0, (F, F, F, F))).map
    b = a.merge(rect(0.2, 0.2, 1.0, 1.0, (O, F, F, F))).map
    assert total_length(b, VectorType.OBSTACLE) == pytest.approx(0.8)
    # and the other way round: a later frontier does not erase an obstacle
    c = b.merge(rect(0.2, 0.2, 1.0, 1.0, (F, F, F, F)))
    assert not c.changed


def test_cells_inside_explored_space_change_nothing_unless_they_see_a_wall():
    big = GridPolyMap(2.0).merge(rect(0.2, 0.2, 1.6, 1.6, (F, F, F, F))).map
    # another robot's smaller view, all inside: merged away without a change
    inner = GridPolyMap(2.0).merge(rect(0.5, 0.5, 1.2, 1.2, (O, O, O, O))).map
    assert big._cells_that_change(list(inner.cells.values()), MergeOptions()) == []
    r = big.merge_cells(list(inner.cells.values()))
    assert not r.changed and r.map is big
    # a view inside whose wall lies on a piece of the map's frontier: not skipped, the
    # frontier under the wall becomes an obstacle
    wall = GridPolyMap(2.0).merge(rect(0.5, 0.2, 1.0, 1.0, (O, F, F, F))).map
    assert len(big._cells_that_change(list(wall.cells.values()), MergeOptions())) == 1
    r = big.merge_cells(list(wall.cells.values()))
    assert r.changed
    assert total_length(r.map, VectorType.OBSTACLE) >= 0.5


def test_merging_the_same_keyframe_twice_changes_nothing():
    kf = star((1.3, 0.7), np.linspace(1.0, 3.0, 40), [O] * 20 + [F] * 20)
    r1 = GridPolyMap(2.0).merge(kf)
    r2 = r1.map.merge(kf)
    assert not r2.changed and r2.map is r1.map


def test_touching_polygons_share_an_edge():
    pmap = GridPolyMap(2.0).merge(rect(0.3, 0.3, 1.0, 1.0, (O, F, O, O))).map
    pmap = pmap.merge(rect(1.0, 0.3, 1.7, 1.0, (O, O, O, F))).map
    assert pmap.explored_area() == pytest.approx(0.98)
    assert len(pmap.cells[(0, 0)].polygons) == 1  # one region, the shared frontier is gone
    assert total_length(pmap, VectorType.FRONTIER) == pytest.approx(0.0)


def test_nearly_coincident_edges_stay_valid():
    pmap = GridPolyMap(2.0).merge(rect(0.3, 0.3, 1.0, 1.0)).map
    for eps in (1e-9, 3e-7, 4e-4, 6e-4):
        pmap = pmap.merge(rect(1.0 + eps, 0.3 - eps, 1.5, 1.0 + eps)).map
    assert_well_formed(pmap)
    assert pmap.explored_area() >= 0.7 * 0.7 + 0.5 * 0.7 - 1e-3


def test_a_sliver_thinner_than_the_grid_is_not_a_change():
    pmap = GridPolyMap(2.0).merge(rect(0.3, 0.3, 1.0, 1.0)).map
    r = pmap.merge(rect(0.3, 0.3, 1.000004, 1.0))  # 4 um: below the 10 um grid
    assert not r.changed


def test_wall_on_a_cell_border_stays_an_obstacle():
    # the right edge lies exactly on x = 2.0, the border between cells (0, 0) and (1, 0)
    pmap = GridPolyMap(2.0).merge(rect(0.5, 0.5, 2.0, 1.5, (F, O, F, F))).map
    assert list(pmap.cells) == [(0, 0)]
    assert total_length(pmap, VectorType.OBSTACLE) == pytest.approx(1.0)
    # free space on the other side of a border becomes a sector on both sides
    pmap2 = GridPolyMap(2.0).merge(rect(0.5, 0.5, 2.0, 1.5, (F, F, F, F))).map
    pmap2 = pmap2.merge(rect(2.0, 0.5, 3.0, 1.5, (F, F, F, F))).map
    assert total_length(pmap2, VectorType.SECTOR) == pytest.approx(2.0)
    assert total_length(pmap2, VectorType.FRONTIER) == pytest.approx(2 * 2.5 + 2 * 1.0)


@pytest.mark.parametrize(("wall_offset_m", "sector"), [(0.01, True), (0.03, True), (0.2, False)])
def test_a_wall_seen_a_little_apart_in_two_cells_leaves_no_frontier_between_them(
    wall_offset_m, sector
):
    # a corridor along y; its wall at x = 3.6 in the cell below y = 2, at 3.6 - offset
    # above (two keyframes, each with its own noise): the 2 m border between the cells
    # is explored on both sides but for the offset
    pmap = GridPolyMap(2.0).merge(rect(2.0, 0.0, 3.6, 2.0, (F, O, F, F))).map
    pmap = pmap.merge(rect(2.0, 2.0, 3.6 - wall_offset_m, 4.0, (F, O, F, F))).map
    s, e, _ = pmap.vectors([VectorType.FRONTIER], [(1, 0), (1, 1)])
    on_border = np.isclose(s[:, 1], 2.0) & np.isclose(e[:, 1], 2.0)
    border_frontier = float(np.hypot(*(e - s)[on_border].T).sum())
    if sector:  # only a gap of a few cm: a sector (the cm across the gap are no way out)
        assert border_frontier == pytest.approx(0.0)
    else:  # a real 20 cm opening stays a frontier
        assert border_frontier >= wall_offset_m - 1e-6
    assert_well_formed(pmap)


def test_only_the_part_of_a_border_facing_a_notch_across_it_stays_a_frontier():
    # cell (0, 0) is explored up to its top border y = 2; the cell above lacks a
    # triangle 0.3 m wide at that border (a corner of a keyframe's fan edge)
    below = TypedPolygon(Ring([(0.1, 0.1), (1.9, 0.1), (1.9, 2.0), (0.1, 2.0)], [O, O, F, O]))
    above = TypedPolygon(
        Ring([(0.1, 2.0), (1.5, 2.0), (1.8, 2.3), (1.9, 2.3), (1.9, 3.9), (0.1, 3.9)], [F] * 6)
    )
    pmap = GridPolyMap(2.0).merge(below).map.merge(above).map
    s, e, _ = pmap.vectors([VectorType.FRONTIER], [(0, 0)])
    # before nodes at the neighbour's corners, the whole 1.8 m border was a frontier
    assert float(np.hypot(*(e - s).T).sum()) == pytest.approx(0.4)  # 1.5 .. 1.9
    s, e, _ = pmap.vectors([VectorType.SECTOR], [(0, 0)])
    assert float(np.hypot(*(e - s).T).sum()) == pytest.approx(1.4)  # 0.1 .. 1.5
    assert_well_formed(pmap)


def test_polygon_with_hole_keeps_the_hole():
    outer = Ring([(0.1, 0.1), (3.9, 0.1), (3.9, 3.9), (0.1, 3.9)], [O] * 4)
    hole = Ring([(1.5, 1.5), (1.5, 2.5), (2.5, 2.5), (2.5, 1.5)], [O] * 4)  # clockwise
    pmap = GridPolyMap(2.0).merge(TypedPolygon(outer, (hole,))).map
    assert pmap.explored_area() == pytest.approx(3.8 * 3.8 - 1.0)
    assert not pmap.is_free(2.0, 2.0) and pmap.is_free(1.0, 1.0)
    assert total_length(pmap, VectorType.OBSTACLE) == pytest.approx(4 * 3.8 + 4.0)


@pytest.mark.parametrize(
    ("xy", "types", "match"),
    [
        ([(0, 0), (0, 1), (1, 1), (1, 0)], [O] * 4, "clockwise"),
        ([(0, 0), (2, 2), (2, 0), (0, 1)], [O] * 4, "not simple"),
        ([(0, 0), (1, 0)], [O, O], "at least 3"),
        ([(0, 0), (1, 0), (math.nan, 1)], [O] * 3, "NaN"),
        ([(0, 0), (1, 0), (2, 0)], [O] * 3, "no area"),
        ([(0, 0), (1, 0), (1, 1)], [O, O, 7], "unknown vector type"),
    ],
)
def test_invalid_polygons_are_rejected_and_the_map_is_untouched(xy, types, match):
    pmap = GridPolyMap(2.0).merge(rect(0.2, 0.2, 1.0, 1.0)).map
    before = dict(pmap.cells)
    with pytest.raises(InvalidPolygonError, match=match):
        pmap.merge(TypedPolygon(Ring(xy, types)))
    assert dict(pmap.cells) == before and pmap.version == 1


def test_ring_with_mismatched_types_is_rejected():
    with pytest.raises(InvalidPolygonError):
        Ring([(0, 0), (1, 0), (1, 1)], [O, O])


# --- queries ---------------------------------------------------------------------------


def test_queries_on_a_room():
    pmap = GridPolyMap(2.0).merge(rect(0, 0, 5, 3, (O, O, O, F))).map
    assert pmap.is_free(1.0, 1.0) and pmap.is_free(4.9, 2.9)
    assert not pmap.is_free(5.5, 1.0) and not pmap.is_free(-1.0, 1.0)
    assert pmap.is_free_many(np.array([[1, 1], [6, 1], [4.5, 0.5]])).tolist() == [True, False, True]
    # nearest obstacle from (1, 1): the bottom wall at 1 m (left side is a frontier)
    assert pmap.nearest_obstacle_distance(1.0, 1.0) == pytest.approx(1.0)
    assert pmap.nearest_obstacle_distance(4.0, 1.5) == pytest.approx(1.0)
    cell, piece = pmap.locate(3.0, 1.0)
    assert cell == (1, 0)
    assert partition_of(pmap.cells[cell]).pieces[piece].contains(3.0, 1.0)
    assert pmap.locate(7.0, 1.0) is None


def test_nearest_obstacle_is_inf_when_none_is_in_range():
    pmap = GridPolyMap(2.0).merge(rect(0, 0, 1, 1, (F, F, F, F))).map
    assert pmap.nearest_obstacle_distance(0.5, 0.5) == math.inf


# --- deltas ----------------------------------------------------------------------------


def test_delta_reproduces_the_map_and_a_gap_is_detected():
    a = GridPolyMap(2.0).merge(rect(0, 0, 3, 3)).map
    b = a.merge(rect(2, 2, 6, 5, (O, F, O, F))).map
    delta = b.delta_since(a.version)
    assert {c.index for c in delta.cells} <= set(b.cells)
    copy = a.apply_delta(delta)
    assert copy.version == b.version
    assert all(copy.cells[k].same_content(b.cells[k]) for k in b.cells)
    with pytest.raises(DeltaGapError):
        GridPolyMap(2.0).apply_delta(b.delta_since(a.version))  # base 1, map at 0
    with pytest.raises(MapError):
        GridPolyMap(4.0).apply_delta(delta)


# --- properties over random keyframes --------------------------------------------------


def test_two_overlapping_squares_merged_at_once_give_the_union_and_its_walls():
    pmap = (
        GridPolyMap(2.0)
        .merge_many([rect(0, 0, 2, 2, (O, O, F, F)), rect(1, 1, 3, 3, (F, F, F, F))])
        .map
    )
    assert pmap.explored_area() == pytest.approx(7.0)
    # the first square's bottom and right walls: 2 m + 1 m outside the second square
    assert total_length(pmap, VectorType.OBSTACLE) == pytest.approx(3.0)
    assert_well_formed(pmap)


def test_merge_many_rejects_an_invalid_polygon_and_leaves_the_map_untouched():
    pmap = GridPolyMap(2.0).merge(rect(0.2, 0.2, 1.0, 1.0)).map
    before = dict(pmap.cells)
    bad = TypedPolygon(Ring([(0, 0), (2, 2), (2, 0), (0, 1)], [O] * 4))
    with pytest.raises(InvalidPolygonError, match="not simple"):
        pmap.merge_many([rect(1, 1, 2, 2), bad])
    assert dict(pmap.cells) == before and pmap.version == 1


def test_a_keyframe_whose_ring_collapses_on_a_cell_border_merges():
    # a noise-free scan of a square room from its centre, refined: GEOS's fast rectangle
    # clip raised "Invalid number of points in LinearRing" on one of its cells
    from polyswarm.config import Config
    from polyswarm.slam.polyslam import PolySlam
    from tests.conftest import room_scan

    slam = PolySlam(Config().slam)
    step = slam.process(room_scan(0.0), (0.0, 0.0, 0.0))
    assert step.keyframe and slam.rejected_keyframes == 0
    assert slam.map.explored_area() > 20.0


def test_a_geos_error_left_in_the_merge_is_a_geometry_error_and_slam_goes_on(monkeypatch):
    from polyswarm.config import Config
    from polyswarm.errors import GeometryError
    from polyswarm.polymap import GridPolyMap as Map
    from polyswarm.slam.polyslam import PolySlam
    from tests.conftest import room_scan

    def fail(*args, **kwargs):
        raise shapely.errors.GEOSException("TopologyException: side location conflict")

    monkeypatch.setattr(Map, "_merge_geometry", fail)
    with pytest.raises(GeometryError, match="GEOS failed"):
        GridPolyMap(2.0).merge(rect(0.0, 0.0, 1.0, 1.0))
    slam = PolySlam(Config().slam)
    step = slam.process(room_scan(0.0), (0.0, 0.0, 0.0))  # logged and counted, no crash
    assert step.keyframe and step.delta is None
    assert slam.rejected_keyframes == 1 and slam.map.cells == {}


def _right_side(pmap: GridPolyMap, kind: VectorType, x0: float, x1: float) -> float:
    """Length of ``kind`` vectors running north between x0 and x1."""
    s, e, _ = pmap.vectors([kind])
    north = (e[:, 1] - s[:, 1] > 0) & (np.abs(e[:, 0] - s[:, 0]) < 1e-6)
    inside = (s[:, 0] >= x0) & (s[:, 0] <= x1)
    return float((e[north & inside, 1] - s[north & inside, 1]).sum())


def test_a_frontier_inside_a_wall_seen_head_on_becomes_that_wall_in_either_order():
    # the wall face runs north at x = 1.0 (explored space on its west side); a grazing
    # view's frontier chord lies 4 cm inside the wall, along 0.6 m of it
    head_on = rect(0.2, 0.2, 1.0, 1.0, (O, O, O, O))
    grazing = rect(0.3, 0.3, 1.04, 0.9, (F, F, F, F))
    snap = MergeOptions(obstacle_snap_behind_m=0.1)
    for first, second in ((head_on, grazing), (grazing, head_on)):
        plain = GridPolyMap(2.0).merge(first).map.merge(second).map
        assert _right_side(plain, VectorType.FRONTIER, 1.03, 1.05) == pytest.approx(0.6)
        pmap = GridPolyMap(2.0).merge(first, snap).map.merge(second, snap).map
        assert _right_side(pmap, VectorType.FRONTIER, 1.03, 1.05) == 0.0
        assert _right_side(pmap, VectorType.OBSTACLE, 1.03, 1.05) == pytest.approx(0.6)
        assert_well_formed(pmap)
    # more than the allowed depth inside: the chord stays a frontier
    deep = rect(0.3, 0.3, 1.15, 0.9, (F, F, F, F))
    pmap = GridPolyMap(2.0).merge(head_on, snap).map.merge(deep, snap).map
    assert _right_side(pmap, VectorType.FRONTIER, 1.14, 1.16) == pytest.approx(0.6)


def test_a_frontier_across_a_doorway_in_line_with_the_wall_stays_a_frontier():
    # wall at x = 1.0 with a 1 m doorway (y 0.5-1.5) seen head-on; a frontier 5 cm
    # behind the wall's line spans wall and doorway: its middle lies beside no wall
    xy = [(0.2, 0.2), (1.0, 0.2), (1.0, 0.5), (1.0, 1.5), (1.0, 1.8), (0.2, 1.8)]
    head_on = TypedPolygon(Ring(xy, [O, O, F, O, O, O]))
    grazing = rect(0.3, 0.3, 1.05, 1.7, (F, F, F, F))
    snap = MergeOptions(obstacle_snap_behind_m=0.1)
    pmap = GridPolyMap(2.0).merge(head_on, snap).map.merge(grazing, snap).map
    assert _right_side(pmap, VectorType.FRONTIER, 1.04, 1.06) == pytest.approx(1.4)


def test_a_frontier_in_front_of_a_wall_whose_growth_is_too_thin_to_keep_becomes_that_wall():
    # SLAM ignores growth thinner than min_growth_m along walls (lidar noise): a chord
    # 4 cm in front of a wall seen head-on later, in a passage 8 cm wide (the growth lies
    # along its walls), can then never close by growing
    grazing = rect(0.2, 0.2, 0.96, 0.28, (O, F, O, O))
    head_on = rect(0.5, 0.2, 1.0, 0.28, (O, O, O, F))
    thin = MergeOptions(min_growth_m=0.05)
    plain = GridPolyMap(2.0).merge(grazing, thin).map.merge(head_on, thin).map
    assert _right_side(plain, VectorType.FRONTIER, 0.95, 0.97) == pytest.approx(0.08)
    snap = MergeOptions(min_growth_m=0.05, obstacle_snap_front_m=0.08)
    pmap = GridPolyMap(2.0).merge(grazing, snap).map.merge(head_on, snap).map
    assert _right_side(pmap, VectorType.FRONTIER, 0.95, 0.97) == 0.0
    assert _right_side(pmap, VectorType.OBSTACLE, 0.95, 0.97) == pytest.approx(0.08)
    # in a room 0.8 m wide the same 4 cm lie along no old wall: they are kept
    grazing = rect(0.2, 0.2, 0.96, 1.0, (O, F, O, O))
    head_on = rect(0.5, 0.2, 1.0, 1.0, (O, O, O, F))
    plain = GridPolyMap(2.0).merge(grazing, thin).map.merge(head_on, thin).map
    assert _right_side(plain, VectorType.FRONTIER, 0.95, 0.97) == 0.0
    assert _right_side(plain, VectorType.OBSTACLE, 0.99, 1.01) == pytest.approx(0.8)


def test_thin_growth_along_a_wall_is_dropped_and_thin_growth_between_frontiers_kept():
    thin = MergeOptions(min_growth_m=0.05)
    # creep: the same room seen again with its east wall 2 cm further out
    room = GridPolyMap(2.0).merge(rect(0.2, 0.2, 1.0, 1.8), thin).map
    crept = room.merge(rect(0.2, 0.2, 1.02, 1.8), thin).map
    assert crept.explored_area() == pytest.approx(room.explored_area(), abs=1e-9)
    # a pocket: a room whose east side is a frontier 4 cm short of a corridor seen from
    # elsewhere (the sliver a keyframe fan leaves across a door), then a view of the
    # pocket. It lies between frontiers, far from the walls: it fills
    two = GridPolyMap(2.0).merge(rect(0.2, 0.2, 1.0, 1.8, (O, F, O, O)), thin).map
    two = two.merge(rect(1.04, 0.2, 1.8, 1.8, (O, O, O, F)), thin).map
    assert not two.is_free(1.02, 1.0)
    filled = two.merge(rect(0.9, 0.5, 1.1, 1.5, (F, F, F, F)), thin).map
    assert filled.is_free(1.02, 1.0)
    assert filled.explored_area() == pytest.approx(two.explored_area() + 0.04 * 1.0, abs=1e-6)


# --- merge operations (a keyframe's delta sent as the polygon it merged) ---------------

SLAM_OPTIONS = MergeOptions(0.05, 0.05, 0.01, 0.1, 0.08)


def _op(pmap: GridPolyMap, polygon: TypedPolygon, options=SLAM_OPTIONS):
    res = pmap.merge(polygon, options)
    digest = cells_digest(res.map.cells[i] for i in res.changed)
    return res.map, MergeOp(pmap.cell_size, pmap.version, res.map.version, polygon, options, digest)


def test_snap_polygon_puts_vertices_on_the_grid_and_drops_vectors_that_vanish():
    p = TypedPolygon(
        Ring([(0, 0), (1.00004, 0.0), (1.0001, 0.0003), (1, 1), (0, 1)], [O, F, O, O, F])
    )
    s = snap_polygon(p, 100)  # 1 mm
    assert s is not None
    k = s.shell.xy * UNITS_PER_M
    assert np.array_equal(k, np.rint(k)) and not (np.rint(k).astype(int) % 100).any()
    # (1.00004, 0) and (1.0001, 0.0003) both land on (1.000, 0.000): that vector is gone,
    # and the vector leaving the merged vertex keeps its type (obstacle)
    assert len(s.shell.xy) == 4
    assert s.shell.types.tolist() == [O, O, O, F]
    sliver = TypedPolygon(Ring([(0, 0), (1, 0), (0.5, 0.0004)], [O, O, O]))
    assert snap_polygon(sliver, 100) is None  # collapsed to a line


@given(st.integers(0, 2**31 - 1))
def test_replaying_merges_reproduces_the_senders_map_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    sender = copy = GridPolyMap(2.0)
    for _ in range(6):
        kf = star(rng.uniform(-3, 3, 2), rng.uniform(0.4, 2.5, 20), rng.integers(0, 2, 20))
        kf = snap_polygon(kf, 100)
        if kf is None:
            continue
        new, op = _op(sender, kf)
        if new.version == sender.version:
            continue
        sender = new
        copy = copy.replay(op).map
    assert copy.version == sender.version and set(copy.cells) == set(sender.cells)
    for i, c in sender.cells.items():
        assert cells_digest([c]) == cells_digest([copy.cells[i]])
        assert copy.cells[i].version == c.version


def test_replay_refuses_a_gap_a_wrong_result_and_ignores_an_old_op():
    a = GridPolyMap(2.0).merge(rect(0, 0, 3, 1)).map
    b, op = _op(a, rect(2.5, 0.2, 5, 0.8, (O, F, O, F)))
    assert a.replay(op).map.version == b.version
    assert b.replay(op).changed == frozenset()  # already applied: unchanged
    with pytest.raises(DeltaGapError, match="applies to version"):
        GridPolyMap(2.0).replay(op)  # the copy is behind: fetch the map
    with pytest.raises(DeltaGapError, match="other cells"):
        a.replay(MergeOp(2.0, op.base_version, op.version, op.polygon, op.options, op.digest ^ 1))
    # a copy at the right version that is not bit-identical is caught by the digest
    other = GridPolyMap(2.0).merge(rect(0, 0, 3, 1.001)).map
    assert other.version == op.base_version
    with pytest.raises(DeltaGapError, match="other cells"):
        other.replay(op)


def test_merge_options_on_the_grid_are_whole_units():
    o = MergeOptions(0.05, 0.123456789, 0.0, 0.1, 0.08).on_grid()
    assert o.obstacle_snap_m == 12346 / UNITS_PER_M and o.min_growth_m == 0.05


def test_a_frontier_continuing_past_a_wall_end_is_not_snapped_to_the_wall():
    # the office door of seed 3: the corridor wall's face ends at a jamb, and a keyframe
    # seen at a grazing angle has a frontier from near that corner into the doorway,
    # 14 degrees off the wall's line and within 4 cm of it; snapped, it was a 16 cm
    # phantom wall that narrowed the door from 0.7 to 0.52 m
    wall_s, wall_e = np.array([[0.0, 1.0]]), np.array([[1.0, 1.0]])
    tree = _segment_tree(wall_s, wall_e)
    a = np.array([[0.96, 1.0], [0.2, 0.97]])  # past the end; along the wall, 3 cm off it
    b = np.array([[1.12, 0.96], [0.8, 0.975]])
    snapped = _obstacle_mask(a, b, wall_s, wall_e, tree, obstacle_snap_m=0.05)
    assert snapped.tolist() == [False, True]


def test_only_neighbours_across_a_changed_border_are_read_again():
    # cell (0, 0) of a 2 m grid: explored space grows inside, then up to its right border
    a = shapely.box(0.5, 0.5, 1.0, 1.0)
    inside = shapely.box(0.5, 0.5, 1.5, 1.5)
    to_right = shapely.box(0.5, 0.5, 2.0, 1.5)
    old = np.array([a, inside], dtype=object)
    new = np.array([inside, to_right], dtype=object)
    assert _across_changed_borders([(0, 0)], old[:1], new[:1], 2.0) == set()
    assert _across_changed_borders([(0, 0)], old[1:], new[1:], 2.0) == {(1, 0)}
    # a region already on its top border that only moves its inner edges: the top
    # neighbour reads the same edge along y = 2 m
    on_top = shapely.box(0.5, 1.0, 1.5, 2.0)
    taller = shapely.Polygon([(0.5, 0.8), (1.5, 1.0), (1.5, 2.0), (0.5, 2.0)])
    assert _across_changed_borders([(0, 0)], np.array([on_top]), np.array([taller]), 2.0) == set()
    # a new region touching the left border at one corner point only (a vertex on it)
    corner = shapely.Polygon([(0.0, 1.0), (1.0, 0.5), (1.0, 1.5)])
    got = _across_changed_borders([(0, 0)], np.array([shapely.Polygon()]), np.array([corner]), 2.0)
    assert got == {(-1, 0)}


def test_a_cell_emptied_by_a_correction_does_not_block_merges_beside_it():
    # a loop correction moved all of a cell's space out: the map keeps it as an empty cell
    # (sent so that receivers drop that space). Merging next to it must still work: a
    # 2 m cell at (1, 0) explored, (2, 0) emptied, then space grows in (1, 0) up to x = 4
    from polyswarm.polymap import Cell

    pmap = GridPolyMap(2.0).merge(rect(2.2, 0.2, 3.6, 1.8, (O, F, O, O))).map
    cells = dict(pmap.cells)
    cells[(2, 0)] = Cell((2, 0), 2.0, ())
    pmap = GridPolyMap(2.0, cells, pmap.version)
    grown = pmap.merge(rect(2.2, 0.2, 4.0, 1.8, (O, F, O, O))).map  # reaches the border
    assert grown.cells[(1, 0)].area == pytest.approx(1.8 * 1.6)
    # and merged as another robot's cell, as the coordinator merges it
    other = GridPolyMap(2.0).merge(rect(2.2, 0.2, 4.0, 1.8, (O, F, O, O))).map
    merged = pmap.merge_cells([other.cells[(1, 0)]]).map
    assert merged.cells[(1, 0)].area == pytest.approx(1.8 * 1.6)


def test_filling_notches_never_turns_a_thin_hole_inside_out():
    # a sliver of wall 12 cm long and under 1 cm thick, an island in explored space
    # (keyframes saw round it): its notches are shallower than 1 cm, and removing
    # every other one left three vertices running counter-clockwise, a cell no decoder
    # takes back (an agent's journal stopped replaying there)
    sliver = [
        [1.1095, 1.0591],
        [1.0976, 1.0449],
        [1.0875, 1.0465],
        [1.0728, 1.0308],
        [1.0652, 1.0369],
        [1.0324, 1.0102],
        [1.0049, 1.0062],
        [1.002, 1.0062],
    ]
    shell = Ring(np.array([[0, 0], [2, 0], [2, 2], [0, 2]], float), np.full(4, O))
    hole = Ring(np.array(sliver), np.full(len(sliver), O))
    assert hole.signed_area < 0
    pmap = GridPolyMap.from_polygons([TypedPolygon(shell, (hole,))], cell_size=2.0)
    for cell in pmap.cells.values():
        for p in fill_notches(cell, 0.01).polygons:
            p.validate()
            assert all(h.signed_area < 0 for h in p.holes)
