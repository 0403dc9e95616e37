"""``bench memory``: heap per keyframe from samples whose answer is known, and on a log."""

import pytest

from polyswarm.benchmarks.memory import heap_growth, run_log
from polyswarm.data import log_paths


def test_heap_growth_per_keyframe():
    rows = [(50, 1.0, 100.0), (100, 1.5, 200.0), (150, 1.7, 200.0), (200, 1.9, 210.0)]
    g = heap_growth(rows)
    assert g["kb_per_keyframe"] == pytest.approx(1000.0 * 0.9 / 150)
    assert g["kb_per_keyframe_second_half"] == pytest.approx(1000.0 * 0.2 / 50)  # 150 -> 200
    assert g["area_growth_second_half"] == pytest.approx(0.05)
    assert heap_growth(rows[:2])["kb_per_keyframe"] is None


def test_slam_on_a_real_log_keeps_kilobytes_per_keyframe():
    fr = next(p for p in log_paths() if p.name.startswith("freiburg"))
    r = run_log(fr, max_keyframes=150)
    assert r["odometry"] == "real" and r["keyframes"] == 150
    assert 0.1 < r["kb_per_keyframe_second_half"] < 100.0  # kilobytes, not megabytes
