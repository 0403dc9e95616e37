"""The coarse-to-fine map search against the one-pass fine search it replaces."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import fft
from shapely.geometry import box

from polyswarm.mapmatch import _view, frame_error
from polyswarm.mapsearch import (
    CONFLICT_WEIGHT,
    HEADING_STEP_RAD,
    PEAK_APART_M,
    PEAKS,
    RESOLUTION_M,
    distinct,
    peaks,
    points_raster,
    search,
)
from tests.test_mapmatch import _seen


def _exhaustive(a, b) -> list[tuple[float, np.ndarray]]:
    """Every heading, every translation at the fine resolution (one FFT correlation a
    heading): the search before 2026-11-28, the reference here."""
    b_clear_xy = (np.argwhere(b.clear > 0) + 0.5) * RESOLUTION_M + b.lo
    b_center = b.walls.mean(axis=0)
    pts = np.concatenate([b.walls, b_clear_xy]) - b_center
    radius = float(np.hypot(pts[:, 0], pts[:, 1]).max())
    nb = int(np.ceil(2 * radius / RESOLUTION_M)) + 2
    fshape = [fft.next_fast_len(n + nb, real=True) for n in a.hit.shape]
    fa = fft.rfft2(a.hit - CONFLICT_WEIGHT * a.clear, fshape)
    fap = fft.rfft2(points_raster(a.walls - a.lo, a.hit.shape), fshape)
    off = np.full(2, radius + RESOLUTION_M)
    found = []
    for th in np.arange(-math.pi, math.pi, HEADING_STEP_RAD):
        c, s = math.cos(th), math.sin(th)
        rot = np.array([[c, -s], [s, c]])
        fbw = fft.rfft2(points_raster((b.walls - b_center) @ rot.T + off, (nb, nb)), fshape)
        fbc = fft.rfft2(points_raster((b_clear_xy - b_center) @ rot.T + off, (nb, nb)), fshape)
        corr = fft.irfft2(fa * np.conj(fbw) - CONFLICT_WEIGHT * fap * np.conj(fbc), fshape)
        for score, ij in peaks(corr, PEAKS, PEAK_APART_M / RESOLUTION_M):
            d = np.array(ij, dtype=float)
            d = np.where(d > np.array(fshape) / 2, d - np.array(fshape), d)
            t = a.lo + d * RESOLUTION_M + off - rot @ b_center
            found.append((score, np.array([t[0], t[1], th])))
    found.sort(key=lambda f: -f[0])
    return distinct(found, PEAKS * 3)


@pytest.mark.parametrize(
    "pose", [(4.0, -3.0, 2.1), (-7.5, 12.0, -0.4), (0.3, 0.2, math.pi)], ids=str
)
def test_the_search_finds_a_moved_part_of_the_building_within_a_cell_and_a_step(pose):
    a = _view(_seen(box(-10, -10, 30, 10)))
    b = _view(_seen(box(8, -8, 26, 9), pose))
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
    a = _view(_seen(box(-10, -10, 30, 10)))
    b = _view(_seen(window, pose))
    fast, full = search(a, b)[:PEAKS], _exhaustive(a, b)[:PEAKS]
    strong = [(s, p) for s, p in full if s >= 0.5 * full[0][0]]
    assert strong
    for (s_fast, p_fast), (s_full, p_full) in zip(fast, strong, strict=False):
        assert s_fast == pytest.approx(s_full, rel=1e-6)
        assert np.allclose(p_fast, p_full, atol=1e-6)
