import numpy as np
import pytest

from polyswarm.frontiers import extract_frontiers, split_polyline
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
