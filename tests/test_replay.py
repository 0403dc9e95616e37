"""Robots' merges replayed on worker processes (``agents.replay``): real processes, the
coordinator's mirror of each copy bit-identical to the robot's map."""

from __future__ import annotations

import os
import signal
import time

import pytest

from agents import persist
from agents.coordinator import Coordinator
from agents.replay import ReplayPool, apply_update
from polyswarm.config import Config
from polyswarm.errors import DeltaGapError, MapError
from polyswarm.slam.follow import Atlas
from protocols.messages import Pose
from tests.conftest import RECTS, ops_of, rect, same, shifted

POLYS = [rect(*r) for r in RECTS]


def settle(c: Coordinator, timeout_s: float = 30.0) -> list:
    """Everything the pool has been sent, collected (a worker starts in about 1 s)."""
    out = c.drain(timeout_s)
    assert not any(r.inflight for r in c.robots.values()), "the pool did not answer"
    return out


def settle_clean(c: Coordinator) -> list:
    """``settle``, every update applied (no gap)."""
    got = settle(c)
    assert not any(isinstance(d, MapError) for _, d in got)
    return got


def with_pool(workers: int = 1, robots: int = 1) -> tuple[Coordinator, ReplayPool]:
    starts = {f"r{k + 1}": (1.0 + k, 1.0, 0.0) for k in range(robots)}
    c = Coordinator(Config(), starts)
    pool = c.use_pool(ReplayPool(workers))
    for rid, (x, y, _) in starts.items():
        c.on_alive(rid, True)
        c.on_pose(rid, 0.0, Pose(x, y, 0.0))
    return c, pool


def test_apply_update_gives_the_cells_a_merge_changed_and_refuses_a_gap():
    robot, ops = ops_of(POLYS[:2])
    m, atlas, delta = apply_update(None, Atlas(), "merge", ops[0])
    m, atlas, delta = apply_update(m, atlas, "merge", ops[1])
    assert same(m, robot)
    assert {c.index for c in delta.cells} == {
        i for i, c in robot.cells.items() if c.version == robot.version
    }
    assert apply_update(m, atlas, "merge", ops[1])[2] is None  # a duplicate: nothing
    _, later = ops_of(POLYS[:3])
    with pytest.raises(MapError):
        apply_update(None, Atlas(), "merge", later[2])  # a first update not at version 0


def test_merges_replayed_on_two_workers_keep_every_copy_bit_identical():
    c, pool = with_pool(workers=2, robots=3)
    with pool:
        robots = {}
        for k, rid in enumerate(c.robots):  # each robot its own corridor, 10 m apart
            polys = [shifted(p, 10.0 * k) for p in RECTS]
            robots[rid], ops = ops_of(polys)
            for t, op in enumerate(ops):
                assert c.on_robot_merge(rid, 0.1 * t, op) is None  # replayed elsewhere
        got = settle(c)
        assert len(got) == 3 * len(POLYS)  # one changed-cells delta per merge
        assert all(not isinstance(d, MapError) for _, d in got)
        for rid, robot in robots.items():
            assert same(c.robot(rid).map, robot)
        assert c.replayed_merges == 3 * len(POLYS)
        assert len(c.worker_replay_cpu_ms) == 3 * len(POLYS)
        c.flush()
        area = sum(r.explored_area() for r in robots.values())
        assert c.merged.explored_area() == pytest.approx(area, rel=1e-6)


def test_a_lost_merge_asks_for_the_map_and_replays_go_on_after_it():
    c, pool = with_pool()
    with pool:
        robot, ops = ops_of(POLYS)
        c.on_robot_merge("r1", 0.1, ops[0])
        c.on_robot_merge("r1", 0.2, ops[2])  # ops[1] was lost on the way
        c.on_robot_merge("r1", 0.3, ops[3])  # fails the same: dropped with it
        got = settle(c)
        gaps = [d for _, d in got if isinstance(d, MapError)]
        assert len(gaps) == 1 and isinstance(gaps[0], DeltaGapError)
        assert c.robot("r1").map.version == ops[0].version  # nothing else applied
        mid, _ = ops_of(POLYS[:4])
        c.on_robot_map("r1", mid)  # the fetched map: the next merge replays on it
        c.on_robot_merge("r1", 0.4, ops[4])
        settle_clean(c)
        assert same(c.robot("r1").map, robot)


def test_a_killed_worker_is_restarted_with_the_maps_it_held():
    c, pool = with_pool()
    with pool:
        robot, ops = ops_of(POLYS)
        for op in ops[:3]:
            c.on_robot_merge("r1", 0.1, op)
        settle(c)
        victim = pool.pids[0]
        os.kill(victim, signal.SIGKILL)
        deadline = time.monotonic() + 10.0
        while pool.restarts == 0 and time.monotonic() < deadline:
            c.collect(wait_s=0.1)  # notices, restarts it and gives it the mirror's map
        assert pool.restarts == 1 and pool.pids[0] != victim
        for op in ops[3:]:
            c.on_robot_merge("r1", 0.2, op)
        settle_clean(c)
        assert same(c.robot("r1").map, robot)


def test_results_of_updates_sent_before_a_whole_map_are_dropped():
    c, pool = with_pool()
    with pool:
        later, ops = ops_of([*POLYS, shifted(RECTS[0], 4.0)])
        robot = ops_of(POLYS)[0]
        for op in ops[:-1]:
            c.on_robot_merge("r1", 0.1, op)
        c.on_robot_map("r1", robot)  # a resync overtakes them
        c.on_robot_merge("r1", 0.2, ops[-1])  # its result comes after theirs (one pipe)
        got = settle_clean(c)
        # only the last one's cells: the others' results came back and were dropped
        assert [d.version for _, d in got] == [ops[-1].version]
        assert same(c.robot("r1").map, later)
        assert len(c.worker_replay_cpu_ms) == 1  # the dropped ones are not counted


def test_workers_journal_the_robots_copies_for_a_restarted_coordinator(tmp_path):
    """With a state folder the workers write each copy (a snapshot and the deltas
    since) off the coordinator's thread; a restart reads back the same maps."""
    c = Coordinator(Config(), {"r1": (1.0, 1.0, 0.0), "r2": (1.0, 11.0, 0.0)})
    with c.use_pool(ReplayPool(2, str(tmp_path))):
        robot1, ops = ops_of(POLYS)
        for op in ops:
            c.on_robot_merge("r1", 0.1, op)
        robot2, _ = ops_of([shifted(r, 10.0) for r in RECTS[:3]])
        c.on_robot_map("r2", robot2)  # a resync: a snapshot
        settle(c)
    _, robots = persist.load_coordinator(tmp_path)
    assert same(robots["r1"], robot1) and same(robots["r2"], robot2)


def test_a_withdrawn_robots_copy_is_journaled_aside_not_restored(tmp_path):
    """A robot withdrawn from the merged map (its frame found wrong): a restarted
    coordinator must not merge its copy again; the copy stays on disk, set aside."""
    c = Coordinator(Config(), {"r1": (1.0, 1.0, 0.0), "r2": (1.0, 11.0, 0.0)})
    with c.use_pool(ReplayPool(1, str(tmp_path))):
        robot1, ops = ops_of(POLYS)
        for op in ops:
            c.on_robot_merge("r1", 0.1, op)
        robot2, ops2 = ops_of([shifted(r, 10.0) for r in RECTS[:3]])
        for op in ops2:
            c.on_robot_merge("r2", 0.1, op)
        c.withdraw("r2")  # its merges still on their way
        settle(c)
        for _ in range(50):  # the worker sets the journal aside after its updates
            if not (tmp_path / "coordinator-robots" / "r2.polymap").exists():
                break
            time.sleep(0.05)
        c.collect(0.5)  # the results of its merges, replayed before the drop
        assert "r2" not in c.robots  # do not bring it back
    _, robots = persist.load_coordinator(tmp_path)
    assert set(robots) == {"r1"} and same(robots["r1"], robot1)
    aside = persist.load_map(tmp_path / "coordinator-robots" / "withdrawn" / "r2-0.polymap")
    assert aside is not None  # nothing it mapped is lost
    j = tmp_path / "coordinator-robots" / "withdrawn" / "r2-0.journal"
    assert same(persist._replay_journal(j, aside), robot2)


def test_workers_of_a_killed_coordinator_stop_themselves():
    """SIGKILL of the coordinator's process leaves no replay or merge process behind."""
    import subprocess
    import sys

    code = (
        "import time\n"
        "from agents.merger import MergeProcess\n"
        "from agents.replay import ReplayPool\n"
        "from polyswarm.config import Config\n"
        "from polyswarm.polymap import GridPolyMap\n"
        "pool = ReplayPool(2)\n"
        "merger = MergeProcess(GridPolyMap(2.0), Config().nav)\n"
        "print(*pool.pids, merger.pid, flush=True)\n"
        "time.sleep(60)\n"
    )
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        workers = [int(w) for w in parent.stdout.readline().split()]
        assert len(workers) == 3 and all(_alive(w) for w in workers)
        parent.kill()
        parent.wait(10.0)
        deadline = time.monotonic() + 20.0
        while any(_alive(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(w) for w in workers)
    finally:
        parent.kill()


def _alive(pid: int) -> bool:
    try:  # a zombie has exited: its parent (here init) has not reaped it yet
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def test_launch_counts_a_childs_own_children_in_its_memory():
    """The coordinator's memory in ``metrics.json`` includes its replay processes."""
    import subprocess
    from types import SimpleNamespace

    from polyswarm.runners.children import _process_tree, _rss_mb

    proc = subprocess.Popen(["bash", "-c", "sleep 30 & wait"])
    try:
        deadline = time.monotonic() + 10.0
        while len(_process_tree(proc.pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        tree = _process_tree(proc.pid)
        assert tree[0] == proc.pid and len(tree) == 2  # bash and its sleep
        alone = _rss_mb(SimpleNamespace(proc=SimpleNamespace(pid=tree[1], poll=lambda: None)))
        assert _rss_mb(SimpleNamespace(proc=proc)) > alone > 0.0
    finally:
        proc.kill()
        proc.wait()
