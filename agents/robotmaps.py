"""The coordinator's copies of the robots' maps: deltas applied, merges and
corrections replayed (here or on a pool of processes), whole maps fetched, robots
withdrawn. A mixin of ``agents.coordinator.Coordinator``."""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING

from agents.replay import Replayed, ReplayPool
from polyswarm.errors import DeltaGapError, MapError
from polyswarm.frames.jointgraph import KeyframeLedger
from polyswarm.frames.sighting import SIGHTING_SLACK_M
from polyswarm.polymap import GridPolyMap, MapDelta, MergeOp
from polyswarm.slam.follow import Atlas, CorrectionOp, largest_move_m, replay_correction
from protocols.chunks import MapKind
from protocols.mapcodec import (
    decode_correction,
    decode_delta,
    decode_merge,
)

if TYPE_CHECKING:
    from agents.coordinator import RobotInfo

log = logging.getLogger(__name__)

# at the end of a run, the replay pool's last updates are waited for this long (s): with
# 25 robots on one replay process its results ran 1.7 s behind (p95, bench cycle)
DRAIN_TIMEOUT_S = 10.0
# a merge of robots' cells waits this long at most for the replays on their way (s).
# Merging without them cost coverage in 4 of 4 maze runs (at 150 s: 58 -> 45 %, 45 ->
# 41 %): a robot's latest view missed the merge by a replay's time, then waited a period
FLUSH_WAIT_S = 0.5


class RobotMaps:
    """The robots' map copies of ``Coordinator`` (see the module)."""

    def on_robot_delta(self, rid: str, stamp_s: float, delta: MapDelta) -> None:
        """Apply a robot's delta to its copy of the robot's map; its cells are merged at
        the next ``flush``.

        Raises DeltaGapError when the robot's delta does not apply (fetch its map)."""
        self.now = max(self.now, stamp_s)
        info = self.robot(rid)
        if self.pool is not None:  # in order behind the robot's merges
            return self._to_pool(info, "delta", delta, stamp_s)
        if info.map is None:
            if delta.base_version > 0:
                raise _gap(rid, delta)
            info.map = GridPolyMap(delta.cell_size)
        with self.timed("deltas"):
            info.map = info.map.apply_delta(delta)
        self.applied_deltas += 1
        self._check_behind(info)
        self._pending.setdefault(rid, set()).update(c.index for c in delta.cells)

    def on_robot_merge(self, rid: str, stamp_s: float, op: MergeOp) -> MapDelta | None:
        """Replay a robot's merge on the copy of its map (bit-identical by construction);
        the cells it changed as a delta (for the journal), or None if it was old.

        Raises DeltaGapError when it does not apply or replays differently (fetch its map)."""
        self.now = max(self.now, stamp_s)
        info = self.robot(rid)
        if op.keyframe is not None and op.keyframe not in info.ledger.keyframes:
            info.ledger.merged(op.keyframe, op.polygon)
        if self.pool is not None:
            return self._to_pool(info, "merge", op, stamp_s)
        if info.map is None:
            if op.base_version > 0:
                raise DeltaGapError(f"first merge of {rid} starts at version {op.base_version}")
            info.map = GridPolyMap(op.cell_size)
        c0 = time.thread_time()
        with self.timed("replay"):
            res = info.map.replay(op)
        self.replay_cpu_ms.append((time.thread_time() - c0) * 1e3)
        if op.keyframe is not None:
            info.atlas.add(op.keyframe, op.polygon, op.options)
        if not res.changed:
            return None
        info.map = res.map
        self.replayed_merges += 1
        self._check_behind(info)
        self._pending.setdefault(rid, set()).update(res.changed)
        changed = tuple(res.map.cells[i] for i in sorted(res.changed))
        return MapDelta(op.cell_size, op.base_version, op.version, changed)

    def on_robot_correction(self, rid: str, stamp_s: float, op: CorrectionOp) -> MapDelta:
        """Replay a robot's correction (keyframes its loop closure moved) on the copy of
        its map; the cells it changed as a delta (for the journal). The merged map's
        cells it changed are merged afresh at the next ``flush``.

        Raises DeltaGapError when it does not apply or replays differently (fetch its map)."""
        self.now = max(self.now, stamp_s)
        info = self.robot(rid)
        info.ledger.corrected(op.moves)
        if self.pool is not None:
            return self._to_pool(info, "correct", op, stamp_s)
        if info.map is None:
            raise DeltaGapError(f"correction of {rid} before any of its map")
        with self.timed("replay"):
            info.map, info.atlas, changed = replay_correction(info.map, info.atlas, op)
        self._corrected(info, stamp_s, largest_move_m(op), {c.index for c in changed})
        return MapDelta(op.cell_size, op.base_version, op.version, tuple(changed))

    def _corrected(self, info: RobotInfo, stamp_s: float, moved_m: float, idxs: set) -> None:
        self.corrections += 1
        if moved_m > SIGHTING_SLACK_M:
            info.corrected_s = stamp_s
        self._check_behind(info)
        self._pending.setdefault(info.id, set()).update(idxs)
        self._rebuild |= idxs

    def _to_pool(self, info: RobotInfo, kind: str, op, stamp_s: float) -> None:
        """Send an update to the robot's replay worker; ``collect`` brings in its cells."""
        with self.timed("replay"):
            self.pool.update(info.id, info.epoch, kind, op, stamp_s)
        info.inflight += 1
        info.queued = max(info.queued, op.version)

    def _set_map(self, info: RobotInfo, pmap: GridPolyMap | None, atlas: Atlas | None = None):
        """The robot's map copy replaced whole (and its atlas, if given; else kept)."""
        info.map = pmap
        if self.pool is None:
            if atlas is not None:
                info.atlas = atlas
            return
        info.epoch += 1  # updates on their way were for the map replaced
        info.inflight = 0
        with self.timed("replay"):
            self.pool.set_map(info.id, info.epoch, pmap, atlas)

    def use_pool(self, pool: ReplayPool) -> ReplayPool:
        """Replay robots' updates on ``pool`` from now on (the maps held go to it)."""
        self.pool = pool
        for info in self.robots.values():
            if info.map is not None:
                self._set_map(info, info.map, info.atlas)
        return pool

    def take_in(self) -> list[tuple[str, MapDelta | MapError]]:
        """``collect``, or when a merge is due ``drain`` for up to ``FLUSH_WAIT_S``: a
        robot's latest view must not miss the merge by a replay's time."""
        return self.drain(FLUSH_WAIT_S) if self._merge_due() else self.collect()

    def drain(self, timeout_s: float = DRAIN_TIMEOUT_S) -> list[tuple[str, MapDelta | MapError]]:
        """``collect`` until the pool has replayed every update sent to it (or
        ``timeout_s`` passed)."""
        out: list[tuple[str, MapDelta | MapError]] = []
        if self.pool is None:
            return out
        deadline = time.monotonic() + timeout_s
        with self.timed("collect"):  # waiting delays the cycle as much as working
            out += self.collect()
            while any(r.inflight for r in self.robots.values()):
                left = deadline - time.monotonic()
                if left <= 0:
                    log.warning("replay processes still busy after %.1f s", timeout_s)
                    break
                out += self.collect(wait_s=min(left, 0.1))
        return out

    def collect(self, wait_s: float = 0.0) -> list[tuple[str, MapDelta | MapError]]:
        """What the replay pool finished since the last call, applied to the robots' map
        copies (their cells are merged at the next ``flush``): per update, the cells it
        changed (for the journal) or the MapError that asks for the robot's map. Robots
        whose worker died are given their maps again (their atlases are lost with it, as
        on a restart of the coordinator: their next correction fetches the map).
        ``wait_s``: how long to wait for a first result when none is there."""
        if self.pool is None:
            return []
        out: list[tuple[str, MapDelta | MapError]] = []
        with self.timed("collect"):
            done, lost = self.pool.poll(wait_s)
            for r in done:
                if r.rid not in self.robots:  # withdrawn (``withdraw``) since it was sent
                    continue
                got = self._collected(r)
                if got is not None:
                    out.append((r.rid, got))
            for rid in lost:
                if rid in self.robots:
                    self._set_map(self.robots[rid], self.robots[rid].map)
        return out

    def _collected(self, r: Replayed) -> MapDelta | MapError | None:
        info = self.robot(r.rid)
        if r.epoch != info.epoch:  # sent before its map was replaced
            return None
        info.inflight = max(0, info.inflight - 1)
        self.worker_replay_cpu_ms.append(r.cpu_ms)
        self.replay_lag_ms.append((time.perf_counter() - r.sent_s) * 1e3)
        self.now = max(self.now, r.stamp_s)
        if r.error is not None:
            info.epoch += 1  # what is still on its way fails the same: drop it
            info.inflight = 0
            self._check_behind(info)
            return DeltaGapError(f"{r.kind} of {r.rid}: {r.error}")
        if r.delta is None:
            return None
        base = info.map if info.map is not None else GridPolyMap(r.delta.cell_size)
        info.map = base.apply_delta(r.delta)
        idxs = {c.index for c in r.delta.cells}
        if r.kind == "correct":
            self._corrected(info, r.stamp_s, r.moved_m, idxs)
        else:
            self.replayed_merges += r.kind == "merge"
            self.applied_deltas += r.kind == "delta"
            self._check_behind(info)
            self._pending.setdefault(r.rid, set()).update(idxs)
        return r.delta

    def on_robot_update(self, rid: str, stamp_s: float, kind: MapKind, wire: bytes):
        """A robot's map update as its MapChunk carried it: decoded and applied; for a
        merge or a correction the cells it changed (or None), for cells the delta itself.
        With a replay pool it is only sent there: None (``collect`` has the outcome).

        Raises DecodeError on bad bytes, MapError (DeltaGapError) when it does not apply."""
        with self.timed("decode"):
            if kind == MapKind.MERGE:
                op = decode_merge(wire)
            elif kind == MapKind.CORRECT:
                op = decode_correction(wire)
            else:
                op = decode_delta(wire)
        if kind == MapKind.MERGE:
            return self.on_robot_merge(rid, stamp_s, op)
        if kind == MapKind.CORRECT:
            return self.on_robot_correction(rid, stamp_s, op)
        self.on_robot_delta(rid, stamp_s, op)
        return op if self.pool is None else None

    def on_robot_map(self, rid: str, pmap: GridPolyMap, atlas: Atlas | None = None) -> None:
        """A robot's full map (resync, or handed over with its ``atlas`` from exploring
        alone): nothing it mapped is lost."""
        info = self.robot(rid)
        if info.map is not None and info.map.version >= pmap.version:
            return
        if info.map is not None:  # corrections missed: cells that lost space are merged afresh
            old = info.map.cells
            self._rebuild |= {i for i, c in old.items() if not c.same_content(pmap.cells.get(i))}
        self._set_map(info, pmap, atlas)
        if atlas is not None:
            info.ledger = KeyframeLedger.from_atlas(atlas)
        self._check_behind(info)
        self._pending.setdefault(rid, set()).update(pmap.cells)

    def withdraw(self, rid: str, why: str = "") -> RobotInfo:
        """A robot leaves the swarm's map and plan (its frame was found wrong,
        ``agents.anchoring``; or, ``why``, it leaves a waiting team's coordinator): the
        merged cells its copy reached are merged afresh from the other robots' copies at
        the next flush, its target is free. Its copy, pose and state are returned: nothing
        it mapped is lost, it goes on in a frame of its own (or another coordinator's)."""
        info = self.robots.pop(rid)
        self._pending.pop(rid, None)
        if info.map is not None:
            self._rebuild |= set(info.map.cells)
        if self.pool is not None:  # its worker journals its copy aside (persist)
            self.pool.drop(rid)
        self._wake = True
        if why:
            log.info("robot %s leaves this coordinator: %s", rid, why)
        else:
            log.warning("robot %s withdrawn from the merged map", rid)
        return info


def _gap(rid: str, delta: MapDelta) -> MapError:
    return DeltaGapError(f"first delta of {rid} starts at version {delta.base_version}")
