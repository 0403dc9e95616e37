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
    # replayed on a worker process: its processor time and the lag it adds are reported
    assert res["replay_workers"] == 1 and r["replay_workers_cpu_s"] > 0.0
    assert 0.0 < r["replay_lag_p50_ms"] <= r["replay_lag_p95_ms"]
    assert "collect" in shares
    # merged on a process of its own: likewise
    assert res["merge_process"] and r["merge_process_cpu_s"] > 0.0
    assert 0.0 < r["merge_lag_p50_ms"] <= r["merge_lag_p95_ms"]


def test_replays_and_merges_on_the_coordinators_thread_report_no_processes():
    res = cycle.run(("rooms",), robots=2, sim_s=8.0, replay_workers=0, merge_process=False)
    r = res["worlds"]["rooms"]
    assert r["replayed_merges"] > 3 and r["replay_workers_cpu_s"] == 0.0
    assert r["replay_lag_p95_ms"] is None and "collect" not in r["stage_share"]
    assert r["merge_process_cpu_s"] == 0.0 and r["merge_lag_p95_ms"] is None
