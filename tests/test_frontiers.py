import numpy as np
import pytest

from polyswarm.explore.frontiers import extract_frontiers, split_polyline
from polyswarm.explore.targets import TargetCache, frontier_targets, sliver_frontiers
from polyswarm.nav.navgraph import NavGraph
from polyswarm.polymap import GridPolyMap
from tests.conftest import F, O, rect


def test_frontier_chains_across_cells():
    # 5 m wide room, frontier on the top side, crossing three cells
    pmap = GridPolyMap(2.0).merge(rect(0.5, 0.5, 5.5, 1.5, (O, O, F, O))).map
    segs = extract_frontiers(pmap)
    assert len(segs) == 1
    seg = segs[0]
    assert seg.length_m == pytest.approx(5.0)
    assert np.allclose(seg.midpoint, (3.0, 1.5))
    # free space on the left of the frontier: it runs right to left along the top
    assert seg.start[0] > seg.end[0]


def test_short_frontiers_are_dropped_and_long_ones_split():
    pmap = GridPolyMap(2.0).merge(rect(0.5, 0.5, 6.5, 1.5, (O, F, F, O))).map
    segs = extract_frontiers(pmap, min_length_m=2.0)
    assert [round(s.length_m, 6) for s in segs] == [7.0]
    parts = extract_frontiers(pmap, max_length_m=3.0)
    assert len(parts) == 3 and sum(s.length_m for s in parts) == pytest.approx(7.0)


def test_split_polyline_keeps_length():
    pts = np.array([[0, 0], [4, 0], [4, 3]], dtype=float)
    pieces = split_polyline(pts, 2.0)
    lengths = [np.hypot(*np.diff(p, axis=0).T).sum() for p in pieces]
    assert len(pieces) == 4 and np.allclose(lengths, 1.75)


def test_a_frontier_facing_a_sliver_of_unexplored_space_is_no_target():
    # a 4 m x 2 m room whose top is a frontier; then explored space from 10 cm above it
    # (a sliver of unexplored space between two keyframes' fans): nothing to see there
    room = rect(0.2, 0.2, 3.8, 1.9, (O, O, F, O))
    pmap = GridPolyMap(2.0).merge(room).map
    graph = NavGraph.build(pmap, 0.3)
    assert len(frontier_targets(pmap, graph, 0.4, 4.0)) == 1  # the top: room to explore
    above = rect(0.2, 2.0, 3.8, 3.8, (F, O, O, O))
    pmap = pmap.merge(above).map
    graph = NavGraph.build(pmap, 0.3)
    segs = extract_frontiers(pmap, 0.4, 4.0)
    assert len(segs) == 2  # both sides of the sliver are still frontiers on the map...
    assert sliver_frontiers(pmap, segs).all()
    assert frontier_targets(pmap, graph, 0.4, 4.0) == []  # ... but neither is a target


def test_cached_targets_are_those_computed_afresh_and_follow_map_changes(monkeypatch):
    import polyswarm.explore.targets

    monkeypatch.setattr(polyswarm.explore.targets, "GAIN_WEIGHT", 1.0)  # the area is cached too
    # two rooms 12 m apart, each with an open side; the second room then grows
    left = rect(0.2, 0.2, 3.8, 3.8, (O, F, O, O))
    right = rect(14.2, 0.2, 17.8, 3.8, (O, O, O, F))
    pmap = GridPolyMap(2.0).merge(left).map.merge(right).map
    cache = TargetCache()

    def both(pmap):
        graph = NavGraph.build(pmap, 0.3)
        cached = frontier_targets(pmap, graph, 0.4, 4.0, cache=cache)
        fresh = frontier_targets(pmap, graph, 0.4, 4.0)
        assert [t.goal.tolist() for t in cached] == [t.goal.tolist() for t in fresh]
        assert [t.utility_m for t in cached] == [t.utility_m for t in fresh]
        return cached

    first = both(pmap)
    assert len(first) == 2 and len(cache.entries) == 2
    kept = {id(f) for f in cache.entries.values()}
    assert len(both(pmap)) == 2  # nothing changed: every fact reused
    assert {id(f) for f in cache.entries.values()} == kept
    # the right room opens towards the left one: its frontier moves, the other stays
    pmap = pmap.merge(rect(12.2, 0.2, 14.4, 3.8, (O, O, O, F))).map
    second = both(pmap)
    assert len(second) == 2
    assert len({id(f) for f in cache.entries.values()} & kept) == 1
    assert min(t.frontier.points[:, 0].min() for t in second) < 13.0
    # each open side looks onto a whole half disc of unexplored space
    assert all(t.utility_m > 3.6 + 10.0 for t in second)
    # the split chains kept are this map's: one per frontier chain
    assert len(cache.pieces) == len({t.frontier.chain for t in second})
    # the same map and graph again (a cycle on an event): the segments are reused whole
    graph = NavGraph.build(pmap, 0.3)
    again = [frontier_targets(pmap, graph, 0.4, 4.0, cache=cache) for _ in range(2)]
    assert [t.frontier for t in again[0]] == [t.frontier for t in again[1]]  # same objects
    assert [t.goal.tolist() for t in again[1]] == [t.goal.tolist() for t in second]


def _chains_by_search(starts: np.ndarray, ends: np.ndarray) -> list[list[int]]:
    """The chaining rule written out plainly: a vector's successor is the first unused
    vector (index order) starting on its end point, else within one grid step."""
    from polyswarm.polymap import UNITS_PER_M

    qs = np.rint(starts * UNITS_PER_M).astype(np.int64).tolist()
    qe = np.rint(ends * UNITS_PER_M).astype(np.int64).tolist()
    n = len(qs)

    def successor(k, used):
        for dx in (0, -1, 1):
            for dy in (0, -1, 1):
                for j in range(n):
                    if not used[j] and j != k and qs[j] == [qe[k][0] + dx, qe[k][1] + dy]:
                        return j
        return None

    none = [False] * n
    has_pred = [False] * n
    for k in range(n):
        if (j := successor(k, none)) is not None:
            has_pred[j] = True
    used, chains = [False] * n, []
    for k in [k for k in range(n) if not has_pred[k]] + list(range(n)):
        if used[k]:
            continue
        chain, used[k] = [k], True
        while (j := successor(chain[-1], used)) is not None:
            chain.append(j)
            used[j] = True
        chains.append(chain)
    return chains


def test_chain_vectors_follows_the_rule_with_shared_and_nearly_shared_points():
    from polyswarm.explore.frontiers import chain_vectors

    rng = np.random.default_rng(11)
    for _ in range(30):
        # a few points on a coarse lattice, so that many vectors share start points (a
        # frontier vertex where several chains meet), some moved by one grid step
        lattice = rng.integers(-3, 4, (12, 2)) * 0.5
        pick = rng.integers(0, len(lattice), (40, 2))
        s, e = lattice[pick[:, 0]].copy(), lattice[pick[:, 1]].copy()
        s[rng.random(40) < 0.2] += 1e-5 * rng.choice([-1, 1], 2)
        got = [c.tolist() for c in chain_vectors(s, e)]
        assert got == _chains_by_search(s, e)
        assert sorted(k for c in got for k in c) == list(range(40))  # each vector once


def test_unexplored_area_behind_a_frontier():
    from polyswarm.explore.targets import GAIN_RADIUS_M, unexplored_behind

    half_disc = 0.5 * np.pi * GAIN_RADIUS_M**2
    # a room whose top is open onto unexplored space: a whole half disc behind it
    room = rect(0.2, 0.2, 3.8, 1.9, (O, O, F, O))
    pmap = GridPolyMap(2.0).merge(room).map
    (seg,) = extract_frontiers(pmap, 0.4, 4.0)
    assert unexplored_behind(pmap, [seg])[0] == pytest.approx(half_disc)
    # explored space 10 cm behind it (a sliver between two fans): almost nothing
    sliver = pmap.merge(rect(0.2, 2.0, 3.8, 3.8, (F, O, O, O))).map
    segs = extract_frontiers(sliver, 0.4, 4.0)
    assert (unexplored_behind(sliver, segs) < 0.02 * half_disc).all()
    # a mapped wall 1 m behind it hides what lies beyond: less than the open half disc,
    # more than the 1 m x 3.6 m strip straight in front
    walled = pmap.merge(rect(-2.0, 2.9, 6.0, 4.0, (O, O, O, O))).map
    (seg,) = extract_frontiers(walled, 0.4, 4.0)
    area = unexplored_behind(walled, [seg])[0]
    assert 3.6 < area < 0.5 * half_disc
