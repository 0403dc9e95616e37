"""The soak's memory figures, on memory traces whose answers are known."""

import pytest

from polyswarm.benchmarks.load import memory_growth


def _rows(mb, kf=None):
    kf = kf or [0] * len(mb)
    return [(5.0 * k, m, f) for k, (m, f) in enumerate(zip(mb, kf, strict=True))]


def test_flat_memory_does_not_grow():
    g = memory_growth(_rows([20.0] + [100.0] * 19))
    assert g["growth"] == 0.0 and g["growth_second_half"] == 0.0
    assert g["mb_first_last"] == [20.0, 100.0]  # the imports before the first tenth
    assert g["kb_per_keyframe"] is None  # not a robot


def test_a_leak_shows_in_the_second_half():
    mb = [100.0 + k for k in range(20)]  # 1 MB per sample
    g = memory_growth(_rows(mb))
    assert g["growth_second_half"] == pytest.approx((119.0 - 110.0) / 110.0)
    assert g["growth"] == pytest.approx((119.0 - 102.0) / 102.0)


def test_memory_per_keyframe_is_the_slope_from_the_first_keyframe():
    kf = [0, 0, 10, 20, 30, 40, 50]
    mb = [20.0, 90.0, 100.0, 100.5, 101.0, 101.5, 102.0]  # 50 kB per keyframe once mapping
    g = memory_growth(_rows(mb, kf))
    assert g["kb_per_keyframe"] == pytest.approx(0.05 * 1024.0)


def test_too_few_keyframes_or_samples_give_no_figure():
    assert memory_growth(_rows([1.0, 2.0]))["growth"] is None
    assert memory_growth(_rows([90.0, 91.0, 92.0], [0, 5, 10]))["kb_per_keyframe"] is None
