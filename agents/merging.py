"""When and where the coordinator merges the robots' changed cells into the merged map:
batched at most every ``MERGE_PERIOD_S``, on a process of its own or here. A mixin of
``agents.coordinator.Coordinator``."""

from __future__ import annotations

import logging
import time

from agents.merger import Merged, MergeJob, MergeLostError, MergeProcess, merge_step
from polyswarm.errors import MapError
from polyswarm.polymap import MapDelta

log = logging.getLogger(__name__)

MERGE_PERIOD_S = 1.0  # robots' changed cells are merged at least this often (batched)


class MergeSchedule:
    """The merge scheduling of ``Coordinator`` (see the module)."""

    def flush_due(self) -> bool:
        if self.merger is not None and self.merger.ready():
            return True  # a merge came in: publish it
        return self._merge_due()

    def _merge_due(self) -> bool:
        changed = self._pending or self._rebuild or any(r.inflight for r in self.robots.values())
        busy = self.merger is not None and self.merger.busy
        return bool(changed) and not busy and self._merge_period_passed()

    def _merge_period_passed(self) -> bool:
        return self.now - self._last_flush >= MERGE_PERIOD_S

    def flush(self, wait_s: float = 0.0, send: bool = False) -> MapDelta | None:
        """Merge the robots' cells changed since the last flush; the merged map's delta.
        With a merge process: apply its last job's result (waiting up to ``wait_s`` for
        it) and send it the cells changed since, once a merge period passed since the
        last job or when asked to (``send``, or waiting); the delta is what came in.

        A cell that fails to merge is logged and stays in its robot's map; the robot's
        next change of it, or a resync, retries it."""
        base = self.merged.version
        if self.merger is not None:
            self._merge_on_process(wait_s, send or wait_s > 0)
            return None if self.merged.version == base else self.merged.delta_since(base)
        self._last_flush = self.now
        if self._pending or self._rebuild:
            t0, c0 = time.perf_counter(), time.thread_time()
            self.merged, delta = merge_step(self.merged, self.graph, self._merge_job())
            if delta is not None:
                self._index = None
            self.spent("merge", (time.perf_counter() - t0) * 1e3, (time.thread_time() - c0) * 1e3)
        return None if self.merged.version == base else self.merged.delta_since(base)

    def _merge_job(self) -> MergeJob:
        """The robots' cells changed since the last merge, and every robot's cells around
        the merged cells corrections changed (those are merged afresh: a ghost wall or
        a frontier a correction closed leaves the merged map too)."""
        todo, self._rebuild = self._rebuild, set()
        reach = {(i + di, j + dj) for i, j in todo for di in (-1, 0, 1) for dj in (-1, 0, 1)}
        rebuild = [
            r.map.cells[ix]
            for r in sorted(self.robots.values(), key=lambda r: r.id)
            if r.map is not None
            for ix in sorted(reach)
            if ix in r.map.cells
        ]
        cells = []
        for rid, idxs in sorted(self._pending.items()):
            m = self.robots[rid].map
            cells += [m.cells[i] for i in sorted(idxs - todo) if m is not None and i in m.cells]
        self._pending = {}
        e = self.cfg.explore
        facts = (e.min_frontier_length_m, e.max_frontier_length_m, self.sensor)
        return MergeJob(
            tuple(cells),
            frozenset(todo),
            tuple(rebuild),
            self._merge_options,
            facts,
            time.perf_counter(),
        )

    def _merge_on_process(self, wait_s: float, send: bool) -> None:
        """Apply the merge process's result, if in; send it the next job, if any is due.
        Sent as soon as a result is in, 25 robots kept the process busy all the time:
        it took the replay process's core and cycles waited for it (18 in 60 s)."""
        with self.timed("merge"):
            try:
                got = self.merger.result(wait_s)
            except MergeLostError as e:
                self._merge_here(e)
                got = None
            if got is not None:
                self._take_merge(got)
            due = self._pending or self._rebuild
            if due and not self.merger.busy and (send or self._merge_period_passed()):
                rids = set(self._pending)
                self._in_merge = (rids, self._merge_job())
                self.merger.submit(self._in_merge[1])
                self._last_flush = self.now
                if wait_s > 0:
                    self._merge_on_process(wait_s, send)

    def _take_merge(self, got: Merged) -> None:
        """A merge process's result applied: the merged map, graph, matrix and facts."""
        try:
            merged = self.merged.apply_delta(got.delta) if got.delta is not None else None
        except MapError as e:  # not the map it was sent: never seen, but never lost either
            self._merge_here(e)
            return
        self._in_merge = None
        self.merger_cpu_ms.append(got.cpu_ms)
        self.merge_lag_ms.append((time.perf_counter() - got.sent_s) * 1e3)
        if merged is not None:
            self.merged = merged
            self.graph.apply(got.patch)
            self._index, self._facts = got.index, (self.merged.version, got.facts)
        self._fresh = True

    def _merge_here(self, why: Exception) -> None:
        """The job on its way merged on this thread (its result will not come, or does
        not apply); the merge process starts again from the map here."""
        log.error("merge process: %s; merging its job here", why)
        if self._in_merge is not None:
            self.merged, delta = merge_step(self.merged, self.graph, self._in_merge[1])
            if delta is not None:
                self._index = None
            self._fresh = True
        self._in_merge = None
        self.merger.reset(self.merged)

    def use_merger(self, merger: MergeProcess) -> MergeProcess:
        """Merge on ``merger``'s process from now on (it is given the merged map)."""
        self.merger = merger
        merger.reset(self.merged)
        return merger

    def _unmerged(self, rid: str) -> bool:
        """Are some of the robot's cells not in the merged map yet?"""
        return rid in self._pending or (self._in_merge is not None and rid in self._in_merge[0])

    def _awaiting_merge(self) -> bool:
        """A merge is on its way and no newer map than the last plan's is in: planning
        waits for it, as it would for a merge on this thread."""
        return self.merger is not None and self.merger.busy and not self._fresh
