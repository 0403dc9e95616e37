"""The coarse-to-fine map search against the one-pass fine search it replaces."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import box

from polyswarm.frames.mapmatch import _view, frame_error
from polyswarm.frames.mapsearch import HEADING_STEP_RAD, PEAKS, search, search_fine
from tests.conftest import seen_map


@pytest.mark.parametrize(
    "pose", [(4.0, -3.0, 2.1), (-7.5, 12.0, -0.4), (0.3, 0.2, math.pi)], ids=str
)
def test_the_search_finds_a_moved_part_of_the_building_within_a_cell_and_a_step(pose):
    a = _view(seen_map(box(-10, -10, 30, 10)))
    b = _view(seen_map(box(8, -8, 26, 9), pose))
    best = search(a, b)[0][1]
    err_m, err_rad = frame_error(best, pose)
    assert err_m < 0.5  # a cell, and a heading off by up to a half step ~10 m out
    assert err_rad <= HEADING_STEP_RAD / 2 + 1e-9


@pytest.mark.parametrize(
    ("window", "pose"),
    [
        (box(8, -8, 26, 9), (4.0, -3.0, 2.1)),
        (box(-2, -7, 12, 8), (-7.5, 12.0, -0.4)),
        (box(0, -3, 24, 3), (1.0, 2.0, 1.2)),  # the corridor alone: ambiguous along it
    ],
    ids=["rooms east", "rooms west", "corridor"],
)
def test_coarse_to_fine_keeps_the_strong_candidates_of_the_fine_search(window, pose):
    """Every candidate of the fine search scoring half the best or more is found, with
    the same score (the same sum, done directly) and pose; weaker ones (a fifth of the
    best here) may differ."""
    a = _view(seen_map(box(-10, -10, 30, 10)))
    b = _view(seen_map(window, pose))
    fast, full = search(a, b)[:PEAKS], search_fine(a, b)[:PEAKS]
    strong = [(s, p) for s, p in full if s >= 0.5 * full[0][0]]
    assert strong
    for (s_fast, p_fast), (s_full, p_full) in zip(fast, strong, strict=False):
        assert s_fast == pytest.approx(s_full, rel=1e-6)
        assert np.allclose(p_fast, p_full, atol=1e-6)
