"""Mutation fuzzing of every decoder of outside bytes (a short run; the full 100,000
inputs per decoder is ``polyswarm fuzz``)."""

from __future__ import annotations

from polyswarm.benchmarks import fuzz


def test_no_decoder_lets_anything_but_its_error_escape():
    res = fuzz.run(count=2000, seed=1)
    assert set(res) == {
        "message",
        "map",
        "delta",
        "merge",
        "correction",
        "whole map as cells",
        "ros-laserscan",
        "ros-odometry",
        "ros-twist",
        "ros-tf",
        "rmw_zenoh-attachment",
    }
    for name, r in res.items():
        assert r["crashes"] == 0, (name, r["examples"])
        assert r["rejected"] > 0 and r["accepted"] + r["rejected"] == r["inputs"]
