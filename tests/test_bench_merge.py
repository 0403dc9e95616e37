"""bench merge's scoring of both methods, on maps and sightings drawn by hand."""

from __future__ import annotations

import numpy as np
from shapely.geometry import box

from polyswarm.benchmarks.merge import _pair_moments
from polyswarm.frames.sighting import Sighting, Track
from polyswarm.se2 import inverse, transform_points
from tests.conftest import profile_with_a_robot_at, seen_map

TRUTH = np.array([4.0, -3.0, 2.1])  # robot 2's frame in robot 1's


def _tracks(seen: bool) -> list[Track]:
    """Robot 1 at its origin; robot 2 drives 0.6 m a second from its own origin through
    3 places 1.5 m apart; robot 1's lidar sees it there when ``seen``."""
    one, two = Track(), Track()
    for k in range(7):
        there = TRUTH[:2] + 0.6 * np.array([min(k, 3), -max(k - 3, 0)])
        mine = transform_points(inverse(TRUTH), there[None])[0]
        clear = profile_with_a_robot_at(there) if seen else b""
        one.add(Sighting(float(k), (0.0, 0.0, 0.0), clear))
        two.add(Sighting(float(k), (float(mine[0]), float(mine[1]), 0.0)))
    return [one, two]


def _rows(seen: bool) -> list[dict]:
    a = seen_map(box(-1, -8, 16, 9))  # robot 1's map
    b = seen_map(box(8, -8, 25, 9), TRUTH)  # robot 2's, in its own frame
    moments = [(10.0, [a, b]), (15.0, [a, b]), (20.0, [a, b])]
    return _pair_moments(moments, 1, TRUTH, _tracks(seen))


def test_a_frame_seen_is_committed_on_the_second_agreeing_match_and_scored_correct():
    rows = _rows(seen=True)
    assert all(r["overlaps"] and r["ours"]["accepted"] for r in rows)
    assert all(r["ours"]["seen"] >= 3 for r in rows)
    assert not rows[0]["committed"]["accepted"]  # one match is not trusted
    for r in rows[1:]:
        c = r["committed"]
        assert c["accepted"] and c["correct"] and not c["wrong"], c
        assert c["err_m"] < 0.10


def test_a_frame_never_seen_is_accepted_by_the_match_but_never_committed():
    rows = _rows(seen=False)
    assert all(r["ours"]["accepted"] and r["ours"]["seen"] == 0 for r in rows)
    assert not any(r["committed"]["accepted"] for r in rows)
