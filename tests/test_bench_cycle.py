"""``bench cycle`` counts all of the coordinator's work into its cycles."""

from polyswarm.benchmarks import cycle


def test_a_short_exploration_counts_replays_merges_and_planning():
    res = cycle.run(("rooms",), robots=2, sim_s=15.0)
    r = res["worlds"]["rooms"]
    assert r["cycles"] > 10 and r["replayed_merges"] > 5
    assert 0.0 < r["cycle_p50_ms"] <= r["cycle_p95_ms"] <= r["cycle_max_ms"]
    shares = r["stage_share"]
    assert {"replay", "merge", "plan"} <= set(shares)
    assert abs(sum(shares.values()) - 1.0) < 1e-9
    assert res["cycle_p95_ms_worst"] == r["cycle_p95_ms"]
    assert res["target_p95_ms"] is None  # no target is set for 2 robots
