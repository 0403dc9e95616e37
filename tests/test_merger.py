"""Merging on a process of its own (``agents.merger``): a real process, the coordinator's
merged map, graph and frontier facts the same as merging on its own thread."""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys

import numpy as np

from agents.coordinator import Coordinator
from agents.merger import MergeProcess
from polyswarm.config import Config
from polyswarm.explore.targets import map_facts
from polyswarm.nav.navgraph import NavGraph
from protocols.messages import Pose
from tests.conftest import RECTS, ops_of, same, shifted


def coordinators(robots: int = 3) -> tuple[Coordinator, Coordinator, MergeProcess]:
    """Two coordinators: one merging on its thread, one on a merge process."""
    starts = {f"r{k + 1}": (1.0, 1.0 + 10.0 * k, 0.0) for k in range(robots)}
    here, there = Coordinator(Config(), starts), Coordinator(Config(), starts)
    merger = there.use_merger(MergeProcess(there.merged, there.cfg.nav))
    for c in (here, there):
        for rid, (x, y, _) in starts.items():
            c.on_alive(rid, True)
            c.on_pose(rid, 0.0, Pose(x, y, 0.0))
    return here, there, merger


def feed(cs: tuple[Coordinator, ...], first: int, last: int) -> None:
    """Robot k drives its own corridor (10 m apart, the first two overlapping)."""
    for k in range(3):
        dy = 10.0 if k == 2 else 0.3 * k
        polys = [shifted(r, dy) for r in RECTS]
        _, ops = ops_of(polys)
        for c in cs:
            for t, op in enumerate(ops[first:last]):
                c.on_robot_merge(f"r{k + 1}", 0.1 * t, op)


def merged_there(c: Coordinator) -> None:
    """Flush until the merge process has merged everything sent (it starts in ~1 s)."""
    for _ in range(5):
        c.flush(wait_s=30.0)
        if not c.merger.busy and not c._pending:
            return
    raise AssertionError("the merge process did not answer")


def same_graph(a: NavGraph, b: NavGraph) -> bool:
    def flat(g: NavGraph) -> list:
        nodes = sorted((n, tuple(p)) for cg in g.cells.values() for n, p in cg.nodes.items())
        groups = [*(cg.internal for cg in g.cells.values()), *g.borders.values()]
        portals = sorted(
            (e, tuple(p.a), tuple(p.b), p.tight) for grp in groups for e, p in grp.items()
        )
        return [nodes, portals, sorted(g.borders)]

    return flat(a) == flat(b)


def test_a_merge_process_gives_the_map_graph_and_facts_of_a_merge_here():
    here, there, merger = coordinators()
    with merger:
        for first, last in ((0, 2), (2, 5)):  # two rounds: the second changes the first's
            feed((here, there), first, last)
            d_here = here.flush()
            assert there.flush() is None  # sent to the process: nothing in yet
            merged_there(there)
            assert same(there.merged, here.merged) and d_here is not None
            assert same_graph(there.graph, here.graph)
        e = there.cfg.explore
        mine = map_facts(here.merged, here.graph, e.min_frontier_length_m, e.max_frontier_length_m)
        assert len(mine[0]) >= 2  # the corridors' open ends
        version, theirs = there._facts
        assert version == there.merged.version
        assert [s.points.tolist() for s in theirs[0]] == [s.points.tolist() for s in mine[0]]
        assert [f.sliver for f in theirs[1]] == [f.sliver for f in mine[1]]
        assert np.array_equal(theirs[2], mine[2])
        assert len(there.merger_cpu_ms) == 2 and len(there.merge_lag_ms) == 2
        # planning on either gives the same targets
        for c in (here, there):
            c.cycle()
        assert sorted(t.goal.tolist() for t in here.targets.values()) == sorted(
            t.goal.tolist() for t in there.targets.values()
        )


def test_a_killed_merge_process_is_restarted_and_its_job_merged_here():
    here, there, merger = coordinators()
    with merger:
        feed((here, there), 0, 2)
        here.flush()
        merged_there(there)
        victim = merger.pid
        os.kill(victim, signal.SIGKILL)  # the next job goes to a dead process
        feed((here, there), 2, 5)
        here.flush()
        there.flush(send=True)  # within the merge period: sent only when asked to
        assert merger.busy
        merged_there(there)  # notices, merges the job here, restarts it with the map
        assert merger.restarts == 1 and merger.pid != victim
        assert same(there.merged, here.merged)
        assert same_graph(there.graph, here.graph)
        # the restarted process merges the next job
        done = len(there.merger_cpu_ms)
        more, _ = ops_of([shifted(r, 0.0) for r in RECTS] + [shifted(RECTS[0], 4.0)])
        for c in (here, there):
            c.on_robot_map("r1", more)
        here.flush()
        merged_there(there)
        assert len(there.merger_cpu_ms) == done + 1
        assert same(there.merged, here.merged) and same_graph(there.graph, here.graph)


def test_a_graph_patch_brings_a_copy_to_the_updated_graph():
    before, _ = ops_of([shifted(r, 0.0) for r in RECTS[:3]])
    after, _ = ops_of([shifted(r, 0.0) for r in RECTS])
    nav = Config().nav
    g = NavGraph.for_robot(before, nav)
    copy = pickle.loads(pickle.dumps(g))
    changed = {i for i, c in after.cells.items() if c.version > before.version}
    changed |= set(before.cells) - set(after.cells)
    assert changed
    g.update(after, changed)
    copy.apply(pickle.loads(pickle.dumps(g.patch(changed))))
    assert same_graph(copy, g) and not same_graph(copy, NavGraph.for_robot(before, nav))
    assert same_graph(g, NavGraph.for_robot(after, nav))


def test_a_cell_pickles_as_its_content_and_region_only():
    pmap, _ = ops_of([shifted(r, 0.0) for r in RECTS])
    cell = max(pmap.cells.values(), key=lambda c: c.vector_count)
    _ = cell.region, cell.vectors, cell.wall_zone(0.1)  # caches filled
    back = pickle.loads(pickle.dumps(cell))
    assert back.same_content(cell) and back.version == cell.version
    assert back.__dict__["region"].equals_exact(cell.region, 0.0)
    assert "vectors" not in back.__dict__ and "_wall_zones" not in back.__dict__


def test_a_cycle_plans_on_the_last_merge_while_the_next_is_on_its_way():
    """With many robots the merge process is never idle: a cycle must not wait for a
    job when a newer map than its last plan's is in (25 robots: 18 cycles in 60 s)."""
    _, there, merger = coordinators()
    with merger:
        feed((there,), 0, 2)
        merged_there(there)  # a merge is in, not planned on yet
        feed((there,), 2, 5)
        there.flush(send=True)  # the next one on its way...
        os.kill(merger.pid, signal.SIGSTOP)  # ...and held there: no race with its result
        try:
            assert merger.busy and not merger.ready()
            assert there.due()
            there.cycle()
            assert len(there.cycle_ms) == 1  # planned, not put off
            there.now += 60.0
            assert not there.due()  # nothing newer in since: the next plan waits for it
        finally:
            os.kill(merger.pid, signal.SIGCONT)
        merged_there(there)


def test_results_of_jobs_sent_before_a_reset_are_dropped():
    from agents.merger import MergeJob, merge_step
    from polyswarm.polymap import GridPolyMap, cells_digest

    here, _, merger = coordinators()
    merger.close()
    feed((here,), 0, 5)
    e, nav = here.cfg.explore, here.cfg.nav
    facts = (e.min_frontier_length_m, e.max_frontier_length_m, here.sensor)

    def job(robots: list[str]) -> MergeJob:
        cells = tuple(c for r in robots for c in here.robot(r).map.cells.values())
        return MergeJob(cells, frozenset(), (), here._merge_options, facts)

    with MergeProcess(GridPolyMap(2.0), nav) as m:
        m.submit(job(["r1", "r2", "r3"]))
        m.reset(GridPolyMap(2.0))  # twice while it is on its way (its result comes after)
        m.reset(GridPolyMap(2.0))
        m.submit(job(["r3"]))
        got = None
        for _ in range(300):
            got = got or m.result(wait_s=0.1)
        want = merge_step(GridPolyMap(2.0), NavGraph.for_robot(GridPolyMap(2.0), nav), job(["r3"]))
        assert got.delta.version == want[1].version
        assert cells_digest(got.delta.cells) == cells_digest(want[1].cells)


def test_a_process_ending_with_its_merge_process_leaves_no_semaphore_behind(tmp_path):
    """``exit_now`` skips the interpreter's teardown; the worker queues' semaphores must
    still be released (else the resource tracker warns in every coordinator log). Run
    as a script file, as the coordinator is (with ``-c`` the tracker did not warn)."""
    script = tmp_path / "ends.py"
    script.write_text(
        "from agents.merger import MergeProcess\n"
        "from polyswarm.cli import exit_now\n"
        "from polyswarm.config import Config\n"
        "from polyswarm.polymap import GridPolyMap\n"
        "if __name__ == '__main__':\n"
        "    MergeProcess(GridPolyMap(2.0), Config().nav).close()\n"
        "    exit_now(0)\n"
    )
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = {**os.environ, "PYTHONPATH": root}
    done = subprocess.run(
        [sys.executable, str(script)],
        check=False,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert "leaked semaphore" not in done.stderr
