"""Robots nobody told where they start: a whole launch, real processes and Zenoh."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest


@pytest.mark.slow
def test_robots_at_unknown_scattered_starts_are_found_merged_and_explore(tmp_path):
    """Two robots at scattered random starts in the office, told nothing: the second
    explores alone until the coordinator finds its frame by matching maps, then joins
    the merged map. The frame is found within the issue's 0.10 m and 1 degree, and the
    exploration completes with a right map."""
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "polyswarm", "launch", "--robots", "2", "--world", "office"]
    cmd += ["--seed", "2", "--unknown-start", "--speed", "0", "--stop-coverage", "0.99"]
    cmd += ["--wall-limit", "400", "--out", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    m = json.loads((out / "metrics.json").read_text())
    assert m["unanchored"] == [] and set(m["anchors"]) == {"r2"}
    a = m["anchors"]["r2"]
    assert a["err_m"] <= 0.10 and a["err_deg"] <= 1.0, a
    assert m["final_coverage"] >= 0.99 and m["map_iou"] >= 0.95
    assert m["collisions"] == {"walls": 0, "robots": 0}
    log = " ".join((out / "logs" / "coordinator.log").read_text().split())
    # matched, committed, then handed over (never merged in its own frame); the launch
    # stops once 99 % is covered and every frame is placed, which can come between the
    # commit and the hand-over (one run of the suite: r2 committed at 315 s, r1 had
    # covered 99 % alone at 213 s)
    committed = log.index("frame of r2 committed")
    joined = log.find("robot r2 joins the swarm's map")
    assert joined == -1 or committed < joined


def _kill_once_logged(out, name: str, line: str, seen: dict) -> None:
    """``kill_by_pid`` process ``name`` once its log holds ``line``."""
    import time

    from tests.conftest import kill_by_pid

    log = out / "logs" / f"{name}.log"
    deadline = time.monotonic() + 500
    while time.monotonic() < deadline:
        if log.exists() and line in " ".join(log.read_text().split()):
            seen["pid"] = kill_by_pid(out, name)
            return
        time.sleep(0.2)


@pytest.mark.slow
def test_a_coordinator_killed_before_and_after_a_robot_joins_places_it_once(tmp_path):
    """The coordinator dies twice in one launch (one launch for both: CI's time).

    First while r2 explores alone (killed at 15 s, started again at 20 s): no frame is
    persisted while a robot waits, so the new coordinator restores the merged map and
    matches r2 afresh. Then SIGKILLed from outside once r2 has joined the shared map (the
    launch restarts it): r2's poses name the anchor it was sent, so the third
    coordinator takes r2 as placed and does not match it again. r2's frame is right, the
    run reaches 99 %, and nothing either robot shared is lost."""
    import threading

    from tests.conftest import assert_nothing_lost

    out, seen = tmp_path / "run", {}
    line = "robot r2 joins the swarm's map"
    threading.Thread(
        target=_kill_once_logged, args=(out, "coordinator", line, seen), daemon=True
    ).start()
    cmd = [sys.executable, "-m", "polyswarm", "launch", "--robots", "2", "--world", "office"]
    cmd += ["--seed", "2", "--unknown-start", "--speed", "0", "--stop-coverage", "0.99"]
    cmd += ["--fault", "kill:coordinator@15,restart:coordinator@20"]
    cmd += ["--wall-limit", "400", "--out", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "pid" in seen, "r2 never joined, or the coordinator was never killed"
    m = json.loads((out / "metrics.json").read_text())
    log = " ".join((out / "logs" / "coordinator.log").read_text().split())
    runs = log.split("coordinator up")  # what each coordinator process logged
    assert len(runs) == 4, "expected three coordinator processes"
    waiting, joined, placed = runs[1:]
    # (a restarted coordinator logs the restore before it is up: in the run before)
    assert "restored the merged map" in waiting and "frame of r2 committed" not in waiting
    assert "frame of r2 committed" in joined and line in joined
    assert "robot r2 is in the shared frame already" in placed
    assert "frame of r2 committed" not in placed  # not matched again
    assert m["unanchored"] == [] and set(m["anchors"]) == {"r2"}
    a = m["anchors"]["r2"]
    assert a["err_m"] <= 0.10 and a["err_deg"] <= 1.0, a
    assert m["final_coverage"] >= 0.99 and m["map_iou"] >= 0.95
    assert_nothing_lost(out)  # (a robot map the coordinator never wrote fails it too)
