"""The exploration benchmark's run plan (the runs themselves are end-to-end work)."""

from __future__ import annotations

from polyswarm.benchmarks.explore import plan_runs


def test_plan_runs_every_world_robot_count_and_seed_from_the_first_seed():
    runs = plan_runs(["data:loop", "office"], [1, 3], seeds=2, nearest=True, first_seed=5)
    hungarian = [(r.world, r.robots, r.seed) for r in runs if r.strategy == "hungarian"]
    assert hungarian == [
        ("data:loop", 1, 5),
        ("data:loop", 1, 6),
        ("data:loop", 3, 5),
        ("data:loop", 3, 6),
        ("office", 1, 5),
        ("office", 1, 6),
        ("office", 3, 5),
        ("office", 3, 6),
    ]
    # the baseline: 3 robots, on the worlds it is defined for, with the same seeds
    nearest = [(r.world, r.robots, r.seed) for r in runs if r.strategy == "nearest"]
    assert nearest == [("data:loop", 3, 5), ("data:loop", 3, 6)]


def test_plan_runs_start_at_seed_zero_by_default():
    runs = plan_runs(["data:cross"], [1], seeds=3, nearest=True)
    assert [r.seed for r in runs] == [0, 1, 2]  # and no nearest with one robot
