"""Trimming a keyframe to what can change the map (polyswarm.slam.trim), on rooms you can draw."""

import numpy as np
import shapely
from hypothesis import example, given, settings
from hypothesis import strategies as st

from polyswarm.polymap import GridPolyMap, MergeOptions, Ring, TypedPolygon, VectorType
from polyswarm.raycast import cast_rays
from polyswarm.slam.keyframe import keyframe_polygon
from polyswarm.slam.scan import LaserScan, scan_to_points
from polyswarm.slam.trim import trim_keyframe

O, F = VectorType.OBSTACLE, VectorType.FRONTIER
OPTS = MergeOptions(
    min_growth_m=0.05,
    obstacle_snap_m=0.05,
    notch_fill_m=0.01,
    obstacle_snap_behind_m=0.1,
    obstacle_snap_front_m=0.08,
)


def _walls(corners, per_side: int, noise_m: float, types, seed: int = 0) -> TypedPolygon:
    """A polygon through ``corners`` with ``per_side`` vertices on each side, pushed off
    the side by up to ``noise_m`` (a lidar re-observing the walls), side k typed types[k]."""
    rng = np.random.default_rng(seed)
    xy, ty = [], []
    c = np.asarray(corners, float)
    for k in range(len(c)):
        a, b = c[k], c[(k + 1) % len(c)]
        normal = np.array([a[1] - b[1], b[0] - a[0]]) / np.hypot(*(b - a))
        for t in np.linspace(0, 1, per_side, endpoint=False):
            off = 0.0 if t == 0 else rng.uniform(-noise_m, noise_m)
            xy.append(a + t * (b - a) + off * normal)
            ty.append(types[k])
    return TypedPolygon.from_points(np.array(xy), np.array(ty))


def _room(types=(O, O, O, O)) -> GridPolyMap:
    room = TypedPolygon.from_points(
        np.array([[0, 0], [4, 0], [4, 3], [0, 3]], float), np.array(types)
    )
    return GridPolyMap.from_polygons([room], cell_size=2.0)


def _region(pmap: GridPolyMap):
    return shapely.union_all([c.region for c in pmap.cells.values()])


def _length(pmap: GridPolyMap, kind: VectorType) -> float:
    total = 0.0
    for c in pmap.cells.values():
        s, e = c.vectors_of_type(kind)
        total += float(np.hypot(*(e - s).T).sum())
    return total


def test_a_re_observed_room_loses_its_wall_vertices_and_changes_nothing():
    pmap = _room()
    corners = [[0.01, 0.01], [3.99, 0.01], [3.99, 2.99], [0.01, 2.99]]
    kf = _walls(corners, per_side=20, noise_m=0.01, types=(O, O, O, O))
    out = trim_keyframe(kf, pmap, OPTS)
    assert len(out.shell) <= 12  # 80 vertices, of which a few per wall stay
    a = pmap.merge(kf, OPTS).map
    b = pmap.merge(out, OPTS).map
    assert abs(_region(a).area - _region(b).area) < 1e-6
    assert abs(_length(a, O) - _length(b, O)) < 1e-6


def test_new_space_is_kept_vertex_for_vertex():
    pmap = _room()
    # the keyframe runs from inside the room into new space beyond its right wall
    corners = [[3.0, 0.5], [7.0, 0.5], [7.0, 2.5], [3.0, 2.5]]
    kf = _walls(corners, per_side=10, noise_m=0.0, types=(F, O, F, F))
    out = trim_keyframe(kf, pmap, OPTS)
    outside = ~shapely.covers(_region(pmap).buffer(0.05), shapely.points(kf.shell.xy))
    kept = {tuple(p) for p in out.shell.xy}
    assert all(tuple(p) in kept for p in kf.shell.xy[outside])
    assert len(out.shell) < len(kf.shell)  # but the part inside the room went
    a, b = pmap.merge(kf, OPTS).map, pmap.merge(out, OPTS).map
    assert abs(_region(a).area - _region(b).area) < 1e-6
    assert abs(_length(a, F) - _length(b, F)) < 1e-6


def test_walls_beside_an_old_frontier_are_kept_so_they_close_it():
    # the room's top side is a frontier; the keyframe sees a wall there
    pmap = _room((O, O, F, O))
    corners = [[0.01, 0.01], [3.99, 0.01], [3.99, 2.99], [0.01, 2.99]]
    kf = _walls(corners, per_side=20, noise_m=0.005, types=(O, O, O, O))
    out = trim_keyframe(kf, pmap, OPTS)
    top = kf.shell.xy[:, 1] > 2.9
    kept = {tuple(p) for p in out.shell.xy}
    assert all(tuple(p) in kept for p in kf.shell.xy[top])
    a, b = pmap.merge(kf, OPTS).map, pmap.merge(out, OPTS).map
    assert _length(a, F) < 1e-6 and _length(b, F) < 1e-6  # closed either way


def test_nothing_mapped_nothing_trimmed():
    kf = _walls([[0, 0], [4, 0], [4, 3], [0, 3]], 10, 0.01, (O, O, O, O))
    assert trim_keyframe(kf, GridPolyMap(2.0), OPTS) is kf


@settings(max_examples=300, deadline=None)
@given(
    st.floats(-1.5, 1.5),
    st.floats(-1.0, 1.0),
    st.integers(4, 30),
    st.floats(0.0, 0.03),
    st.integers(0, 10_000),
)
def test_trimmed_merge_explores_what_the_keyframe_explores(dx, dy, per_side, noise, seed):
    """Property: merging the trimmed keyframe gives the explored space and the frontiers
    of merging the keyframe, up to slivers thinner than min_growth_m."""
    pmap = _room((O, O, F, O))
    corners = np.array([[0.5, 0.5], [3.5, 0.5], [3.5, 2.5], [0.5, 2.5]]) + np.array([dx, dy])
    kf = _walls(corners, per_side, noise, (O, F, O, F), seed)
    out = trim_keyframe(kf, pmap, OPTS)
    out.validate()
    a, b = _region(pmap.merge(kf, OPTS).map), _region(pmap.merge(out, OPTS).map)
    assert shapely.covers(b.buffer(OPTS.min_growth_m), a)
    assert shapely.covers(a.buffer(OPTS.min_growth_m), b)
    assert abs(a.area - b.area) <= 0.05 * OPTS.min_growth_m * a.length


def _room_with_pillar() -> GridPolyMap:
    """The 4 m x 3 m room with a 0.4 m square pillar at (2.2-2.6, 1.3-1.7), explored
    all around it (the robot drove round it)."""
    shell = Ring(np.array([[0, 0], [4, 0], [4, 3], [0, 3]], float), np.full(4, O))
    pillar = Ring(np.array([[2.2, 1.3], [2.2, 1.7], [2.6, 1.7], [2.6, 1.3]]), np.full(4, O))
    return GridPolyMap.from_polygons([TypedPolygon(shell, (pillar,))], cell_size=2.0)


def test_a_chord_never_swallows_a_mapped_pillar():
    # a keyframe from the left sees the pillar's left face and the shadow behind it;
    # the shadow's chain lies in explored space and so does the chord across its mouth,
    # but the pillar lies between them: trimmed to the chord, the merge would erase it
    pmap = _room_with_pillar()
    xy = [[0.5, 0.5], [1.2, 0.5], [2.0, 0.5], [3.0, 0.5], [3.0, 0.8], [3.0, 1.25]]
    ty = [O, O, O, F, F, F]
    xy += [[2.6, 1.28], [2.2, 1.28], [2.2, 1.5], [2.2, 1.72], [2.6, 1.72]]  # shadow, face
    ty += [F, O, O, F, F]
    xy += [[3.0, 1.75], [3.0, 2.2], [3.0, 2.5], [2.0, 2.5], [1.2, 2.5], [0.5, 2.5]]
    ty += [F, F, O, O, O, O]
    kf = TypedPolygon.from_points(np.array(xy), np.array(ty))
    kf.validate()
    out = trim_keyframe(kf, pmap, OPTS)
    out.validate()
    merged = _region(pmap.merge(out, OPTS).map)
    assert not shapely.intersects(merged, shapely.box(2.25, 1.35, 2.55, 1.65))
    # and the map is what merging the whole keyframe gives
    assert abs(merged.area - _region(pmap.merge(kf, OPTS).map).area) < 1e-6


@settings(max_examples=60, deadline=None)
@given(
    st.floats(2.0, 5.6),
    st.floats(1.5, 4.1),
    st.floats(0.5, 7.5),
    st.floats(0.5, 5.5),
    st.integers(0, 10_000),
)
@example(4.90625, 1.625, 0.6875, 2.84375, 1)  # found by a CI run: a noise sliver, not a trim
@example(4.16796875, 2.126953125, 3.18359375, 2.998046875, 4)  # a 1.1 mm2 sliver (CI)
def test_a_scan_beside_a_pillar_never_trims_it_away(px, py, rx, ry, seed):
    """Property: in a room explored all round a pillar, a lidar keyframe taken anywhere
    and trimmed explores no more of the pillar than the keyframe itself (which cuts a
    corner of it by a few millimetres where a beam's noise and its neighbour's meet)."""
    pillar = shapely.box(px, py, px + 0.4, py + 0.4)
    if shapely.distance(pillar, shapely.Point(rx, ry)) < 0.3:
        return
    shell = Ring(np.array([[0, 0], [8, 0], [8, 6], [0, 6]], float), np.full(4, O))
    hole = [[px, py], [px, py + 0.4], [px + 0.4, py + 0.4], [px + 0.4, py]]
    pmap = GridPolyMap.from_polygons(
        [TypedPolygon(shell, (Ring(np.array(hole), np.full(4, O)),))], cell_size=2.0
    )
    walls = shapely.union(shapely.box(0, 0, 8, 6).boundary, pillar.boundary)
    segs = [np.array(g.coords) for g in shapely.get_parts(walls)]
    s = np.concatenate([c[:-1] for c in segs])
    e = np.concatenate([c[1:] for c in segs])
    rng = np.random.default_rng(seed)
    a = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    r = cast_rays((rx, ry), a, s, e, 30.0) + rng.normal(0, 0.01, len(a))
    kf = keyframe_polygon(
        scan_to_points(LaserScan(r, -np.pi, a[1] - a[0], 0.05, 30.0)), (rx, ry, 0.0), 0.5
    )
    out = trim_keyframe(kf, pmap, OPTS)
    core = pillar.buffer(-0.05)
    trimmed = shapely.intersection(_region(pmap.merge(out, OPTS).map), core).area
    whole = shapely.intersection(_region(pmap.merge(kf, OPTS).map), core).area
    # the keyframe's own noisy corner of the pillar may survive the merge of the trimmed
    # polygon where the merge of the whole dropped it as a sliver (6e-5 m2, example below)
    own = shapely.intersection(kf.to_shapely(), core).area
    # (snapped to the map's grid on merging; slivers up to 10 mm2 where two merges differ)
    assert trimmed <= max(whole, own) + 1e-5


def test_a_cells_frontier_and_obstacle_views_are_its_vectors_of_each_type():
    # a 4 x 3 m room with one open side (x = 4) on 2 m cells: the cell at (1, 0) holds
    # 2 m of the open side as frontier and 2 m of bottom wall as obstacle
    pmap = _room(types=(O, F, O, O))
    c = pmap.cells[(1, 0)]
    for kind, view in ((O, c.obstacle_vectors), (F, c.frontier_vectors)):
        s, e = c.vectors_of_type(kind)
        assert np.array_equal(view[0], s) and np.array_equal(view[1], e)
    fs, fe = c.frontier_vectors
    assert np.allclose(fs[:, 0], 4.0) and np.allclose(fe[:, 0], 4.0)
    assert abs(float(np.hypot(*(fe - fs).T).sum()) - 2.0) < 1e-9
    os_, oe = c.obstacle_vectors
    assert abs(float(np.hypot(*(oe - os_).T).sum()) - 2.0) < 1e-9
