"""Every script in examples/ runs on small inputs and prints what its docstring says."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from polyswarm.io.tum import write_tum

ROOT = Path(__file__).resolve().parents[1]
OFFICE_MAP = ROOT / "docs" / "img" / "office-3-robots.polymap"


def example(name: str, *args, cwd=None) -> str:
    p = subprocess.run(
        [sys.executable, str(ROOT / "examples" / f"{name}.py"), *map(str, args)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        cwd=cwd,
    )
    assert p.returncode == 0, p.stderr[-2000:]
    return p.stdout


def test_there_are_a_few_examples_and_each_is_tested_here():
    names = {p.stem for p in (ROOT / "examples").glob("*.py")}
    assert len(names) <= 6
    assert names <= set(Path(__file__).read_text().split('"'))


def test_explore_in_one_process(tmp_path):
    out = example("explore_in_one_process", "rooms", 1, 20, cwd=tmp_path)
    assert "% of the free space after" in out
    assert (tmp_path / "explored.png").stat().st_size > 0


def test_map_a_recording(shared_data, tmp_path):
    out = example("map_a_recording", shared_data / "bags" / "neato-square.bag", tmp_path / "m.png")
    assert "keyframes" in out and "m2 explored" in out
    assert (tmp_path / "m.png").stat().st_size > 0


def test_map_vs_truth():
    out = example("map_vs_truth", OFFICE_MAP, "office")
    iou = float(out.split()[1].rstrip(";"))
    assert 0.9 < iou <= 1.0  # the README's map of the office


def test_plan_timing():
    out = example("plan_timing", OFFICE_MAP, 3)
    assert "navigation graph built" in out and "planning ms: p50" in out


def test_robot_drift(tmp_path):
    t = np.arange(0.0, 10.0, 0.5)
    truth = np.stack([t, np.zeros_like(t), np.zeros_like(t)], axis=1)
    est = truth + np.array([0.0, 0.1, 0.0])  # 0.1 m to the left all along
    (tmp_path / "trajectories").mkdir()
    write_tum(tmp_path / "trajectories" / "r1.tum", t, est)
    write_tum(tmp_path / "trajectories" / "r1_truth.tum", t, truth)
    out = example("robot_drift", tmp_path, 3)
    assert "r1: largest error 0.10 m, final 0.10 m" in out
