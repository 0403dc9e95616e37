"""Merging robots' cells into the swarm's map, on the coordinator's thread or on a
process of its own.

What a merge costs the coordinator after the replays moved to their processes
(``agents.replay``): merging the robots' changed cells into the merged map, updating the
navigation graph and its matrix, and the frontier facts that depend on the map alone
(``polyswarm.explore.targets.map_facts``) - together 60-85 % of the thread's work with 3 robots
(``polyswarm bench cycle``, stages ``merge`` and ``plan``). ``merge_step`` does all of
it, given the cells; ``MergeProcess`` runs it on a process, one job at a time, while the
coordinator plans on the map it has. The coordinator sends the robots' cells from its
copies and applies what comes back (the merged map's delta, the graph's changed cells
and borders, the matrix, the facts): its map and graph are those of the process, bit for
bit, because they are the same cells.

Messages to the process (pickled by the sender):

* ``("reset", merged, nav)``: the merged map whole (a start, a restore, a restart);
* ``("job", MergeJob)``: cells to merge;
* ``None``: stop.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import pickle
import time
from dataclasses import dataclass

from agents.replay import receive, start_process, stop_process
from polyswarm.config import NavConfig
from polyswarm.errors import PolyswarmError
from polyswarm.explore.assign import GraphIndex
from polyswarm.explore.targets import Sensor, TargetCache, map_facts
from polyswarm.nav.navgraph import GraphPatch, NavGraph
from polyswarm.polymap import GridPolyMap, MapDelta, MergeOptions

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MergeJob:
    """Robots' cells to merge into the merged map, and the merged cells to rebuild afresh
    (a correction took space out of them) from ``rebuild``: every robot's cells around."""

    cells: tuple  # robots' changed cells, in order
    todo: frozenset  # merged cells rebuilt afresh
    rebuild: tuple  # every robot's cells around ``todo``
    options: MergeOptions
    # frontier facts of the new map: (min length m, max length m, the robots' Sensor)
    facts_params: tuple[float, float, Sensor]
    sent_s: float = 0.0  # the sender's ``time.perf_counter``


@dataclass(frozen=True)
class Merged:
    """What a job changed: the merged map's delta (None: nothing), the graph's changed
    part, its matrix, and the frontier facts of the new map."""

    delta: MapDelta | None
    patch: GraphPatch | None
    index: GraphIndex | None
    facts: tuple | None
    cpu_ms: float = 0.0  # the process's time for the job
    sent_s: float = 0.0


def merge_cells(merged: GridPolyMap, cells: list, options: MergeOptions) -> GridPolyMap:
    """``cells`` merged into ``merged``. A cell GEOS fails on is logged and left out (it
    stays in its robot's map: the robot's next change of it, or a resync, retries it)."""
    try:
        return merged.merge_cells(cells, options).map
    except PolyswarmError as e:
        if len(cells) == 1:
            cell = cells[0].index
            log.error("cell %s could not be merged (kept in the robot's map): %s", cell, e)
            return merged
    for c in cells:  # find the bad cell; merge the others (a rare path)
        merged = merge_cells(merged, [c], options)
    return merged


def rebuild_cells(
    merged: GridPolyMap, todo: frozenset, cells: tuple, options: MergeOptions
) -> GridPolyMap:
    """The merged cells ``todo`` merged afresh from ``cells`` (every robot's cells around
    them: borders are typed against neighbours)."""
    if not todo:
        return merged
    try:
        fresh = GridPolyMap(merged.cell_size).merge_cells(list(cells), options)
    except PolyswarmError as e:  # merged over what they hold; robots' next changes retry
        log.error("merged cells could not be rebuilt after a correction: %s", e)
        return merge_cells(merged, [c for c in cells if c.index in todo], options)
    return merged.with_cells_of(fresh.map, todo)[0]


def merge_step(
    merged: GridPolyMap, graph: NavGraph, job: MergeJob
) -> tuple[GridPolyMap, MapDelta | None]:
    """The job's merge: the new merged map and its delta (None: nothing changed); the
    graph is updated in place."""
    base = merged.version
    merged = rebuild_cells(merged, job.todo, job.rebuild, job.options)
    merged = merge_cells(merged, list(job.cells), job.options)
    if merged.version == base:
        return merged, None
    delta = merged.delta_since(base)
    graph.update(merged, {c.index for c in delta.cells})
    return merged, delta


def _serve(inbox, results, _state_dir) -> None:
    """The merge process's loop: the merged map, its graph and the frontier facts' cache."""
    merged = graph = None
    cache = TargetCache()
    while (raw := receive(inbox)) is not None:
        msg = pickle.loads(raw)
        if msg[0] == "reset":
            _, merged, nav = msg
            graph = NavGraph.for_robot(merged, nav)
            cache = TargetCache()
            continue
        job: MergeJob = msg[1]
        c0 = time.thread_time()
        try:
            merged, delta = merge_step(merged, graph, job)
            patch = None if delta is None else graph.patch({c.index for c in delta.cells})
            index = None if delta is None else GraphIndex.build(graph)
            lo, hi, sensor = job.facts_params
            facts = None if delta is None else map_facts(merged, graph, lo, hi, cache, sensor)
        except Exception:  # a bug must not leave the coordinator waiting: it merges itself
            log.exception("merge job failed")
            results.send(None)
            continue
        cpu_ms = (time.thread_time() - c0) * 1e3
        results.send(Merged(delta, patch, index, facts, cpu_ms, job.sent_s))


class MergeProcess:
    """One process merging robots' cells for the coordinator, one job at a time:
    ``submit`` a job, ``result()`` when it is done. A process that died is restarted
    (``result`` raises ``MergeLostError``: the coordinator merges that job itself and
    gives the process its map again)."""

    def __init__(self, merged: GridPolyMap, nav: NavConfig) -> None:
        self._ctx = mp.get_context("spawn")  # no fork of a process with Zenoh threads
        self._nav = nav
        self._proc = start_process(self._ctx, _serve, None)
        self.busy = False
        self._stale = 0  # results of jobs sent before a reset, still to come: dropped
        self.restarts = 0
        self.reset(merged)

    @property
    def pid(self) -> int:
        return self._proc.proc.pid

    def reset(self, merged: GridPolyMap) -> None:
        """The merged map whole (a job in flight is forgotten: its result is dropped)."""
        self._send(("reset", merged, self._nav))
        self._stale += self.busy
        self.busy = False

    def ready(self) -> bool:
        """Is a result (or news of the process's death) waiting?"""
        try:
            return (self.busy or self._stale > 0) and self._proc.results.poll()
        except OSError:
            return True

    def submit(self, job: MergeJob) -> None:
        if self.busy:
            raise RuntimeError("a merge job is in flight")
        self._send(("job", job))
        self.busy = True

    def _send(self, msg: tuple) -> None:
        self._proc.inbox.put(pickle.dumps(msg, pickle.HIGHEST_PROTOCOL))

    def result(self, wait_s: float = 0.0) -> Merged | None:
        """The job's result once it is done (None: not yet). Raises MergeLostError when the
        process died or the job failed: the job is lost, the process restarted."""
        conn = self._proc.results
        try:
            while self.busy or self._stale:
                if not conn.poll(wait_s):
                    break
                got = conn.recv()
                if self._stale:  # the result of a job sent before a reset (in order)
                    self._stale -= 1
                    continue
                self.busy = False
                if got is None:
                    raise MergeLostError("the merge process failed on a job (logged there)")
                return got
        except (EOFError, OSError):
            pass
        if self._proc.proc.is_alive():
            return None
        code = self._proc.proc.exitcode
        log.error("merge process exited (code %s): restarting it", code)
        stop_process(self._proc, 0.0)
        self.restarts += 1
        self._proc = start_process(self._ctx, _serve, None)
        self.busy, self._stale = False, 0
        raise MergeLostError(f"the merge process exited (code {code})")

    def close(self) -> None:
        stop_process(self._proc, None)

    def __enter__(self) -> MergeProcess:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class MergeLostError(PolyswarmError):
    """A merge job's result will not come (its process died or failed on it)."""
