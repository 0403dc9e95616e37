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


def _row(world, robots, seed, t99, profile="turtlebot3", **over):
    row = {
        "world": world,
        "robots": robots,
        "strategy": "hungarian",
        "seed": seed,
        "profile": profile,
        "t99_s": t99,
        "unexplored_reachable_m2": 0.5 if t99 else 40.0,
        "map_iou": 0.97,
        "wall_collisions": 0,
        "robot_collisions": 0,
        "crashed_processes": [],
        "wall_time_s": 100.0,
    } | over
    from polyswarm.benchmarks.explore import succeeded

    row["success"] = succeeded(row)
    return row


def test_summary_gives_per_profile_and_world_the_seeds_the_reference_and_the_worst():
    from polyswarm.benchmarks.explore import summarise

    rows = [
        _row("office", 3, 0, 200.0),
        _row("office", 3, 1, 300.0),
        _row("office", 3, 2, None),  # never reached 99 %
        _row("rooms", 3, 0, 50.0, wall_collisions=1),  # reached, but hit a wall
    ]
    refs = {("turtlebot3", "office", 3, seed): 160.0 for seed in range(3)}
    res = summarise(rows, refs | {("turtlebot3", "rooms", 3, 0): 40.0})
    office = res["profiles"]["turtlebot3"]["office"]["3"]
    assert office["t99_s"] == [200.0, 300.0, None]
    assert office["t99_median_s"] == 300.0  # the failed run counts as infinitely slow
    assert office["reference_t99_s"] == 160.0
    assert office["t99_ratio_vs_reference"] == 300.0 / 160.0
    assert office["t99_ratio_vs_reference_worst"] is None  # one run never got there
    assert office["success_rate"] == 2 / 3
    assert office["unexplored_reachable_m2_max"] == 40.0
    rooms = res["profiles"]["turtlebot3"]["rooms"]["3"]
    assert rooms["success_rate"] == 0.0 and rooms["t99_ratio_vs_reference"] == 50.0 / 40.0
    assert res["success_rate"] == 2 / 4 and res["wall_collisions"] == 1


def test_each_seed_of_a_seeded_world_is_divided_by_the_reference_on_its_own_layout():
    from polyswarm.benchmarks.explore import summarise

    rows = [_row("furnished", 3, s, t) for s, t in ((0, 100.0), (1, 300.0), (2, 200.0))]
    refs = {("turtlebot3", "furnished", 3, 0): 100.0, ("turtlebot3", "furnished", 3, 1): 250.0}
    refs[("turtlebot3", "furnished", 3, 2)] = 80.0  # a small layout: the worst ratio
    cell = summarise(rows, refs)["profiles"]["turtlebot3"]["furnished"]["3"]
    assert cell["reference_t99_s"] == 100.0  # the median of the three references
    assert cell["t99_ratio_vs_reference"] == 200.0 / 100.0
    assert cell["t99_ratio_vs_reference_worst"] == 200.0 / 80.0  # seed 0's would be 3.0


def test_plan_runs_carry_the_profile():
    runs = plan_runs(["office"], [3], seeds=1, nearest=False, profile="turtlebot4")
    assert [(r.world, r.profile) for r in runs] == [("office", "turtlebot4")]


def test_unknown_starts_are_compared_with_the_same_starts_told():
    from polyswarm.benchmarks.explore import plan_runs, summarise_unknown

    runs = plan_runs(["office"], [3], 2, True, unknown_start=True)
    assert [(r.seed, r.start) for r in runs] == [
        (0, "scattered"),
        (0, "unknown"),
        (1, "scattered"),
        (1, "unknown"),
    ]  # the nearest-frontier baseline is not part of it

    def row(seed, start, t99, anchors, unanchored=()):
        return {
            "profile": "thesis",
            "world": "office",
            "robots": 3,
            "seed": seed,
            "start": start,
            "t99_s": t99,
            "success": t99 is not None,
            "anchors": anchors,
            "unanchored": list(unanchored),
        }

    good = {"r2": {"err_m": 0.02, "err_deg": 0.1}, "r3": {"err_m": 0.05, "err_deg": 0.3}}
    wrong = {"r2": {"err_m": 4.0, "err_deg": 0.1}}
    res = summarise_unknown(
        [
            row(0, "scattered", 100.0, {}),
            row(0, "unknown", 120.0, good),
            row(1, "scattered", 100.0, {}),
            row(1, "unknown", 150.0, wrong, ["r3"])
            | {"pose_error_m": {"r1": {"median": 0.1, "p95": 0.2, "end": 0.1}}},
        ]
    )["thesis"]["office"]["3"]
    assert res["pose_err_m_p95_max"] == 0.2
    assert res["wrong_merges"] == 1 and not res["all_anchored"]
    assert res["t99_ratio_median"] == 1.35 and res["t99_ratio_worst"] == 1.5
    assert res["frame_err_m_max"] == 4.0
    nobody = summarise_unknown([row(0, "scattered", 100.0, {}), row(0, "unknown", 120.0, {})])
    assert nobody["thesis"]["office"]["3"]["frame_err_m_max"] is None  # not 0 m
