"""Navigation on PolyMaps: hand-checkable maps and a clearance property."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from polyswarm.errors import PlanningError
from polyswarm.nav.navgraph import BUFFER_SEGMENTS, NavGraph, grown_radius
from polyswarm.nav.planner import Planner, path_clearance
from polyswarm.polymap import GridPolyMap, Ring, TypedPolygon, VectorType
from protocols.mapcodec import decode_map
from tests.conftest import O

R = 0.25


def l_corridor() -> GridPolyMap:
    ring = Ring([(0, 0), (2, 0), (2, 8), (10, 8), (10, 10), (0, 10)], [O] * 6)
    return GridPolyMap(2.0).merge(TypedPolygon(ring)).map


def obstacles(pmap):
    s, e, _ = pmap.vectors([VectorType.OBSTACLE])
    return s, e


def test_l_corridor_gives_the_known_shortest_path():
    pmap = l_corridor()
    graph = NavGraph.build(pmap, R)
    path = Planner(pmap, graph).plan((1, 1), (9, 9))
    # taut around the inner corner (2, 8): two tangents of sqrt(50 - R^2) and an arc of
    # radius R over the 73.7 degree turn: 14.46 m (the zero-radius path is 14.14 m)
    exact = 2 * math.sqrt(50 - R * R) + R * math.radians(73.74)
    assert exact - 0.01 <= path.length_m <= exact + 0.03
    assert path_clearance(path.points, *obstacles(pmap)) >= R - 1e-9
    assert np.allclose(path.points[0], (1, 1)) and np.allclose(path.points[-1], (9, 9))


def test_a_gap_narrower_than_the_robot_is_impassable():
    # two rooms joined by a 0.4 m door (narrower than 2 x 0.25 m)
    left = Ring(
        [
            (0, 0),
            (3, 0),
            (3, 1.8),
            (3.5, 1.8),
            (3.5, 0),
            (6, 0),
            (6, 4),
            (3.5, 4),
            (3.5, 2.2),
            (3, 2.2),
            (3, 4),
            (0, 4),
        ],
        [O] * 12,
    )
    pmap = GridPolyMap(2.0).merge(TypedPolygon(left)).map
    graph = NavGraph.build(pmap, R)
    with pytest.raises(PlanningError):
        Planner(pmap, graph).plan((1, 2), (5, 2))
    # a smaller robot fits
    small = NavGraph.build(pmap, 0.15)
    path = Planner(pmap, small).plan((1, 2), (5, 2))
    assert path_clearance(path.points, *obstacles(pmap)) >= 0.15 - 1e-9


def test_a_goal_in_unexplored_space_is_refused():
    pmap = l_corridor()
    planner = Planner(pmap, NavGraph.build(pmap, R))
    with pytest.raises(PlanningError, match="unexplored"):
        planner.plan((1, 1), (6, 4))
    with pytest.raises(PlanningError, match="start"):
        planner.plan((6, 4), (1, 1))


def test_a_robot_standing_in_an_unexplored_sliver_still_plans():
    # the tip of a start scan's blind wedge can stay a thin unexplored hole in the map,
    # right where the robot stands (measured on the loop: one robot never moved)
    outer = Ring([(0, 0), (2, 0), (2, 8), (10, 8), (10, 10), (0, 10)], [O] * 6)
    sliver = Ring([(0.9, 1.0), (0.9, 1.3), (0.92, 1.3), (0.92, 1.0)], [O] * 4)  # clockwise
    pmap = GridPolyMap(2.0).merge(TypedPolygon(outer, (sliver,))).map
    assert not pmap.is_free(0.91, 1.1)
    path = Planner(pmap, NavGraph.build(pmap, R)).plan((0.91, 1.1), (9, 9))
    assert np.allclose(path.points[-1], (9, 9))
    assert path.length_m < 8.0 + 9.0  # about (1, 1) -> (1, 9) -> (9, 9)


def test_graph_is_much_smaller_than_the_pieces_and_updates_incrementally():
    pmap = l_corridor()
    graph = NavGraph.build(pmap, R)
    assert 0 < graph.node_count <= graph.piece_count
    bigger = pmap.merge(
        TypedPolygon(Ring([(10, 8), (14, 8), (14, 10), (10, 10)], [O, O, O, VectorType.FRONTIER]))
    ).map
    changed = {c.index for c in bigger.delta_since(pmap.version).cells}
    updated = NavGraph.build(pmap, R).update(bigger, changed)
    fresh = NavGraph.build(bigger, R)
    assert updated.node_count == fresh.node_count and updated.edge_count == fresh.edge_count
    path = Planner(bigger, updated).plan((1, 1), (13, 9))
    assert path.length_m > 2 * math.sqrt(50)


@st.composite
def rooms(draw):
    """A random room with random box obstacles (pillars) inside."""
    w, h = draw(st.floats(4, 9)), draw(st.floats(4, 9))
    holes = []
    for _ in range(draw(st.integers(0, 4))):
        x, y = draw(st.floats(0.8, w - 1.6)), draw(st.floats(0.8, h - 1.6))
        s = draw(st.floats(0.2, 0.8))
        holes.append(Ring([(x, y), (x, y + s), (x + s, y + s), (x + s, y)], [O] * 4))
    return w, h, holes


@given(rooms(), st.integers(0, 1000))
@settings(max_examples=25, deadline=None)
def test_every_path_keeps_the_radius_from_every_obstacle(room, seed):
    w, h, holes = room
    outer = Ring([(0, 0), (w, 0), (w, h), (0, h)], [O] * 4)
    poly = TypedPolygon(outer, tuple(holes))
    try:
        poly.validate()
    except Exception:
        return  # overlapping pillars
    pmap = GridPolyMap(2.0).merge(poly).map
    planner = Planner(pmap, NavGraph.build(pmap, R))
    rng = np.random.default_rng(seed)
    s, e = obstacles(pmap)
    for _ in range(3):
        a, b = rng.uniform((0.3, 0.3), (w - 0.3, h - 0.3), (2, 2))
        if not (pmap.is_free(*a) and pmap.is_free(*b)):
            continue
        try:
            path = planner.plan(a, b)
        except PlanningError:
            continue
        inner = path.points
        # the first and last legs may start or end closer than R (the robot is there)
        if len(inner) > 3:
            assert path_clearance(inner[1:-1], s, e) >= R - 1e-6
        assert pmap.is_free_many(inner).all()


def test_graph_index_weights_are_path_lengths_through_the_portals():
    from polyswarm.explore.assign import GraphIndex

    # an L-shaped corridor: several pieces and cells, so internal and border edges
    ring = Ring([(0.1, 0.1), (5.9, 0.1), (5.9, 1.9), (1.9, 1.9), (1.9, 5.9), (0.1, 5.9)], [O] * 6)
    pmap = GridPolyMap(2.0).merge(TypedPolygon(ring)).map
    graph = NavGraph.build(pmap, 0.3)
    index = GraphIndex.build(graph)
    edges = [
        *((e, p) for cg in graph.cells.values() for e, p in cg.internal.items()),
        *((e, p) for b in graph.borders.values() for e, p in b.items()),
    ]
    assert edges and index.matrix.nnz == 2 * len(edges)
    for (a, b), portal in edges:
        m = 0.5 * (portal.a + portal.b)
        want = np.hypot(*(graph.point(a) - m)) + np.hypot(*(m - graph.point(b)))
        ia, ib = index.index[a], index.index[b]
        assert index.matrix[ia, ib] == pytest.approx(want)
        assert index.matrix[ib, ia] == pytest.approx(want)


def test_a_goal_past_a_pinch_gives_a_partial_path_only_when_asked():
    # a corridor 2 m wide with a tooth from the floor up to 0.5 m below the ceiling: no
    # room for the 0.6 m disc. The sampled graph lets the route through (an opening from
    # the tooth's tip has clearance at its far end); the exact check cuts it
    ring = Ring([(0, 0), (4, 0), (5, 1.5), (6, 0), (10, 0), (10, 2), (0, 2)], [O] * 7)
    pmap = GridPolyMap(2.0).merge(TypedPolygon(ring)).map
    planner = Planner(pmap, NavGraph.build(pmap, 0.3))
    with pytest.raises(PlanningError):
        planner.plan((1, 1), (9, 1))
    path = planner.plan((1, 1), (9, 1), partial=True)
    assert not path.reaches_goal
    end = path.points[-1]
    assert end[0] < 5.0  # on the start's side of the pinch
    assert np.hypot(*(end - (9, 1))) <= np.hypot(8, 0) - 0.5  # PARTIAL_GAIN_M closer
    assert path_clearance(path.points, *obstacles(pmap)) >= 0.3 - 1e-6
    # a goal on the start's side is reached in full, partial or not
    assert planner.plan((1, 1), (3, 1), partial=True).reaches_goal


def door_rooms(wide_door: bool) -> GridPolyMap:
    """Rooms 0-3 and 3.5-6 (x) by 0-4 (y) with a 0.6 m door at y 0.7-1.3 and, if
    ``wide_door``, a 1.0 m one at y 2.6-3.6."""
    first = [(0, 0), (3, 0), (3, 0.7), (3.5, 0.7), (3.5, 0), (6, 0), (6, 4), (3.5, 4)]
    if wide_door:
        shell = Ring([*first, (3.5, 3.6), (3, 3.6), (3, 4), (0, 4)], [O] * 12)
        pillar = Ring([(3, 1.3), (3, 2.6), (3.5, 2.6), (3.5, 1.3)], [O] * 4)  # clockwise
        return GridPolyMap(2.0).merge(TypedPolygon(shell, (pillar,))).map
    shell = Ring([*first, (3.5, 1.3), (3, 1.3), (3, 4), (0, 4)], [O] * 12)
    return GridPolyMap(2.0).merge(TypedPolygon(shell)).map


def test_a_tight_door_is_passable_at_the_tight_radius_and_a_wider_way_preferred():
    # radius 0.3 m needs 0.62 m (the grown polygon circumscribes the circle, and the
    # samples keep 5 mm); the tight radius 0.23 m (robot 0.2 m + 3 cm of wall error)
    # fits the 0.6 m door
    pmap = door_rooms(wide_door=False)
    with pytest.raises(PlanningError):
        Planner(pmap, NavGraph.build(pmap, 0.3)).plan((1, 1), (5, 1))
    graph = NavGraph.build(pmap, 0.3, tight_radius=0.23)
    path = Planner(pmap, graph).plan((1, 1), (5, 1))
    assert path.reaches_goal
    assert path.length_m == pytest.approx(4.0, abs=0.05)  # straight through the door
    assert path_clearance(path.points, *obstacles(pmap)) >= 0.23 - 1e-6
    assert any(p.tight for n in path.nodes for _, p in graph.neighbours(n))
    # with a 1 m door 1.5 m further round, the path takes it (TIGHT_PENALTY_M = 5 m)
    pmap = door_rooms(wide_door=True)
    path = Planner(pmap, NavGraph.build(pmap, 0.3, tight_radius=0.23)).plan((1, 1), (5, 1))
    at_wall = path.points[(path.points[:, 0] > 2.9) & (path.points[:, 0] < 3.6)]
    assert len(at_wall) and (at_wall[:, 1] > 2.6).all()
    assert path_clearance(path.points, *obstacles(pmap)) >= 0.3 - 1e-6


def test_frontiers_keep_the_frontier_radius_only():
    # a 0.55 m strip off a room, walled below and frontier (unseen) above (and the
    # room's wall above it, seen at a grazing angle): too narrow for 0.3 m on both sides,
    # wide enough for 0.3 m from the wall and 0.1 m from the frontier
    F = VectorType.FRONTIER
    ring = Ring(
        [(0, 0), (4, 0), (4, 0.5), (8, 0.5), (8, 1.05), (4, 1.05), (4, 2), (0, 2)],
        [O, O, O, F, F, F, O, O],
    )
    pmap = GridPolyMap(2.0).merge(TypedPolygon(ring)).map
    with pytest.raises(PlanningError):
        Planner(pmap, NavGraph.build(pmap, 0.3)).plan((1, 1), (7, 0.85))
    path = Planner(pmap, NavGraph.build(pmap, 0.3, frontier_radius=0.1)).plan((1, 1), (7, 0.85))
    assert path.reaches_goal
    assert path_clearance(path.points, *obstacles(pmap)) >= 0.3 - 1e-6
    fs, fe, _ = pmap.vectors([F])
    assert path_clearance(path.points, fs, fe) >= 0.1 - 1e-6


def test_seen_obstacles_the_map_lacks_are_kept_clear_of_like_walls():
    """A wall the map lost (free space on both sides merged through it) but the lidar
    sees: the path goes round its end, the radius away from every seen point."""
    ring = Ring([(0, 0), (8, 0), (8, 4), (0, 4)], [O] * 4)
    pmap = GridPolyMap(2.0).merge(TypedPolygon(ring)).map
    graph = NavGraph.build(pmap, R)
    straight = Planner(pmap, graph).plan((1, 1), (7, 1))
    assert straight.length_m == pytest.approx(6.0, abs=1e-6)
    wall = np.stack([np.full(61, 4.0), np.linspace(0.0, 3.0, 61)], axis=1)  # x = 4, y 0-3
    around = Planner(pmap, graph, seen=wall).plan((1, 1), (7, 1))
    pts = around.points
    assert pts[:, 1].max() >= 3.0 + R - 1e-6  # over the wall's end at y = 3
    dense = np.concatenate([np.linspace(a, b, 50) for a, b in itertools.pairwise(pts)])
    gap = np.min(np.hypot(*(dense[:, None, :] - wall[None, :, :]).transpose(2, 0, 1)))
    assert gap >= R - 1e-6


def test_seen_points_are_grown_into_the_same_shape_as_their_multipoint_buffer():
    """The planner grows seen points one disc each and unions them (GEOS buffers a
    MultiPoint all at once: seconds for 2,000 points); the shape must be the same."""
    rng = np.random.default_rng(3)
    pmap = GridPolyMap(2.0).merge(TypedPolygon(Ring([(0, 0), (4, 0), (4, 4), (0, 4)], [O] * 4))).map
    planner = Planner(pmap, NavGraph.build(pmap, R))
    seen = np.concatenate(
        [rng.uniform(0, 4, (150, 2)), np.c_[np.linspace(1, 3, 41), np.full(41, 2.0)]]
    )
    none = np.zeros((0, 2))
    grown = planner._grown(none, none, np.zeros(0, bool), R, seen)
    reference = shapely.buffer(
        shapely.multipoints(seen), grown_radius(R), quad_segs=BUFFER_SEGMENTS
    )
    assert grown.symmetric_difference(reference).area < 1e-9
    assert grown.area > 0.5 * 16  # not empty: 191 discs over a 4 m square


def test_the_shortest_path_in_a_polygon_never_leaves_it():
    """Random star-shaped polygons (many thin triangles): the path between two inside
    points stays inside. Portals oriented by the centroids' direction put 1 path in 400
    straight through the polygon's boundary (on a PolySLAM office map: four walls)."""
    from polyswarm.nav.planner import _channel

    rng = np.random.default_rng(1)
    tried = 0
    for _ in range(400):
        n = int(rng.integers(8, 40))
        ang = np.sort(rng.uniform(0, 2 * np.pi, n))
        r = rng.uniform(0.3, 5.0, n)
        poly = shapely.set_precision(
            shapely.Polygon(np.stack([r * np.cos(ang), r * np.sin(ang)], 1)), 1e-6
        )
        inner = poly.buffer(-0.01)
        if poly.geom_type != "Polygon" or inner.geom_type != "Polygon" or inner.is_empty:
            continue
        pts = []
        while len(pts) < 2:
            p = rng.uniform(-5, 5, 2)
            if inner.contains(shapely.Point(p)):
                pts.append(p)
        path = _channel(poly, pts[0], pts[1])
        tried += 1
        assert path is not None and poly.buffer(1e-6).covers(shapely.LineString(path))
        assert np.allclose(path[0], pts[0]) and np.allclose(path[-1], pts[1])
    assert tried > 300


def test_the_fallback_path_keeps_only_the_corners_it_needs_and_stays_inside():
    """Portal midpoints through an L-shaped corridor, shortcut: the corner remains, the
    points a straight segment can skip go."""
    from polyswarm.nav.planner import _shortcut

    corridor = shapely.Polygon([(0, 0), (10, 0), (10, 10), (8, 10), (8, 2), (0, 2)])
    mids = np.array([(1, 1), (3, 1), (5, 1), (7, 1), (9, 1), (9, 3), (9, 5), (9, 9)], float)
    path = _shortcut(mids, corridor)
    assert corridor.covers(shapely.LineString(path))
    assert np.allclose(path[0], (1, 1)) and np.allclose(path[-1], (9, 9))
    assert 3 <= len(path) < len(mids)


def test_a_door_reached_along_slivers_of_a_fanned_cell_is_passable():
    """A TurtleBot3 office map (tests/fixtures, 10 cells cropped from a coordinator's
    merged map): the corridor cell below a 0.7 m door is partitioned into a fan of thin
    triangles from its corner at (16, 8). The route's own slivers left no room for the
    0.205 m radius, so the planner found no path, the robot reported the frontier
    past the door unreachable twice, the coordinator blacklisted it and ended the
    mission at 90 %. The cell has plenty of room: the path goes through the door."""
    data = (Path(__file__).parent / "fixtures" / "office_door_slivers.polymap").read_bytes()
    pmap = decode_map(data)
    graph = NavGraph.build(pmap, 0.205, frontier_radius=0.1, tight_radius=0.135)
    start, goal = np.array([15.74, 8.15]), np.array([17.91, 9.10])
    path = Planner(pmap, graph).plan(start, goal)
    assert path.reaches_goal and np.allclose(path.points[-1], goal)
    # through the door: the map's walls end at x 16.98 and 17.80 on y 8.5 (its left
    # jamb is not mapped yet), keeping the radius from every wall
    crossing = np.interp(8.5, path.points[:, 1], path.points[:, 0])
    assert 16.98 + 0.205 <= crossing <= 17.80 - 0.205, crossing
    assert path_clearance(path.points, *obstacles(pmap)) >= 0.205 - 1e-6
    assert path.length_m < np.hypot(*(goal - start)) + 0.5
