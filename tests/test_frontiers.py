import numpy as np
import pytest

from polyswarm.explore import TargetCache, frontier_targets, sliver_frontiers
from polyswarm.frontiers import extract_frontiers, split_polyline
from polyswarm.navgraph import NavGraph
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


def test_cached_targets_are_those_computed_afresh_and_follow_map_changes():
    # two rooms 8 m apart, each with an open side; the second room then grows
    left = rect(0.2, 0.2, 3.8, 3.8, (O, F, O, O))
    right = rect(10.2, 0.2, 13.8, 3.8, (O, O, O, F))
    pmap = GridPolyMap(2.0).merge(left).map.merge(right).map
    cache = TargetCache()

    def both(pmap):
        graph = NavGraph.build(pmap, 0.3)
        cached = frontier_targets(pmap, graph, 0.4, 4.0, cache=cache)
        fresh = frontier_targets(pmap, graph, 0.4, 4.0)
        assert [t.goal.tolist() for t in cached] == [t.goal.tolist() for t in fresh]
        return cached

    first = both(pmap)
    assert len(first) == 2 and len(cache.entries) == 2
    kept = {id(f) for f in cache.entries.values()}
    assert len(both(pmap)) == 2  # nothing changed: every fact reused
    assert {id(f) for f in cache.entries.values()} == kept
    # the right room opens towards the left one: its frontier moves, the other stays
    pmap = pmap.merge(rect(8.2, 0.2, 10.4, 3.8, (O, O, O, F))).map
    second = both(pmap)
    assert len(second) == 2
    assert len({id(f) for f in cache.entries.values()} & kept) == 1
    assert min(t.frontier.points[:, 0].min() for t in second) < 9.0


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
    from polyswarm.frontiers import chain_vectors

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
