"""The coordinator: merges the robots' maps, keeps frontier targets, assigns them.

``Coordinator`` is the logic and knows nothing of Zenoh: the robots' map copies and
their replays, and the merge schedule, here; target allocation in ``agents.allocation``
(a part of the class); ``agents.coordinator_process.run_coordinator`` wires it to a
session (in router mode for the loopback default, so nothing else is installed).

Each cycle (``Coordinator.cycle``; every ``explore.cycle_period_s`` and on events:
a robot reached or failed its target, joined or left):
  1. frontier targets of the merged map (reachable goal points, blacklist applied);
  2. path costs from every robot over the merged map's navigation graph;
  3. assignment by strategy (hungarian / greedy / nearest) with hysteresis;
  4. failures: unreachable, or no progress for a timeout, count against a target (half
     when the robot itself hardly moved: then it is mostly stuck itself); after
     ``blacklist_after_failures`` it is blacklisted. A target reached
     whose frontier is still there after the robot looked at it is blacklisted after
     ``blacklist_after_looks`` such looks;
  5. mission end: no reachable target for ``end_confirm_s`` and ``END_CONFIRM_CYCLES``
     cycles in a row, with every robot's map merged -> the blacklisted targets get one
     more round if the map grew since their last (``RETRY_GROWTH_M2``; one that a look
     left open, only if the merged cells near it changed) -> robots return to their
     start poses -> done.
Robot map deltas are applied to that robot's copy of its map as they arrive (a gap
fetches the robot's full map); the changed cells of all robots are merged into the
global map in one batch (``flush``) every ``MERGE_PERIOD_S`` and before each cycle, so
the navigation graph is updated once per batch and the merged map goes out as one delta.
A robot's loop closure (a correction: keyframes moved) can take space out of its cells;
the merged cells it changed are then merged afresh from every robot's copy, so a ghost
wall or a frontier the correction closed leaves the merged map too.
"""

from __future__ import annotations

import logging
import math
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from agents.allocation import STALLED_M, STALLED_WEIGHT, TargetAllocation
from agents.meeting import Meetings
from agents.merger import Merged, MergeJob, MergeLostError, MergeProcess, merge_step
from agents.replay import Replayed, ReplayPool
from polyswarm.config import Config
from polyswarm.errors import DeltaGapError, MapError
from polyswarm.explore.assign import GraphIndex, Reach, Strategy
from polyswarm.explore.targets import Sensor, Target, TargetCache
from polyswarm.frames.jointgraph import KeyframeLedger
from polyswarm.frames.sighting import SIGHTING_SLACK_M
from polyswarm.nav.navgraph import NavGraph
from polyswarm.polymap import GridPolyMap, MapDelta, MergeOp, MergeOptions
from polyswarm.slam.follow import Atlas, CorrectionOp, largest_move_m, replay_correction
from protocols.mapcodec import (
    decode_correction,
    decode_delta,
    decode_merge,
)
from protocols.messages import (
    MAX_STATUS_POINTS,
    Assignment,
    AssignmentKind,
    CoordinatorStatus,
    MapKind,
    MissionState,
    Pose,
    RobotState,
    RobotStatus,
)

log = logging.getLogger(__name__)

RESEND_S = 5.0  # assignments are repeated this often (a lost message heals)
RESYNC_AFTER_S = 1.0  # a robot's map ahead of ours this long: fetch it whole
# no reachable target for this many cycles in a row (besides explore.end_confirm_s) ends
# the mission: simulated seconds run faster than wall seconds, a loaded coordinator may
# manage a single cycle in end_confirm_s, and one cycle on a lagging map must not end it
END_CONFIRM_CYCLES = 3
# robots whose frames are not found hold the end of the exploration this long (simulated
# s) after the last frontier: matches every 5 s need a few more views of a shared place
FRAME_WAIT_S = 120.0
MERGE_PERIOD_S = 1.0  # robots' changed cells are merged at least this often (batched)
# at the end of a run, the replay pool's last updates are waited for this long (s): with
# 25 robots on one replay process its results ran 1.7 s behind (p95, bench cycle)
DRAIN_TIMEOUT_S = 10.0
# a merge of robots' cells waits this long at most for the replays on their way (s).
# Merging without them cost coverage in 4 of 4 maze runs (at 150 s: 58 -> 45 %, 45 ->
# 41 %): a robot's latest view missed the merge by a replay's time, then waited a period
FLUSH_WAIT_S = 0.5


@dataclass
class RobotInfo:
    id: str
    start: np.ndarray
    alive: bool = False
    pose: np.ndarray | None = None
    map: GridPolyMap | None = None
    # the keyframes its merges carried, to replay its corrections (polyswarm.slam.follow)
    atlas: Atlas = field(default_factory=Atlas)
    # the same keyframes' walls and frames, for the joint pose graph (agents.joint)
    ledger: KeyframeLedger = field(default_factory=KeyframeLedger)
    frame: int = 0  # the anchor its poses name (0: its start was given)
    status: RobotStatus | None = None
    assignment: Assignment | None = None
    sent_t: float = -math.inf
    best_cost: float = math.inf
    progress_t: float = 0.0
    progress_goal: tuple[float, float] | None = None  # the goal best_cost was measured to
    progress_xy: np.ndarray | None = None  # where the robot was at its last progress
    excluded: dict[int, float] = field(default_factory=dict)  # target id -> until
    reached_t: float | None = None  # when the robot reported its target reached
    behind_since: float | None = None  # the robot's map version is ahead of ours since
    announced: int = 0  # the robot's map version, as its poses tell
    pose_t: float = -math.inf  # stamp of the robot's latest pose
    # stamp of its latest correction that moved a keyframe farther than SIGHTING_SLACK_M:
    # its poses sent before are that far off its map now (sightings forget them)
    corrected_s: float = -math.inf
    home_failed: bool = False  # could not drive back to its start (the mission still ends)
    left_over_since: float | None = None  # the assignment has left it over (or it follows)
    # with a replay pool (``agents.replay``): the count of whole maps given to its worker
    # (results of updates sent before the last are dropped), its updates on the way, and
    # the newest version among them
    epoch: int = 0
    inflight: int = 0
    queued: int = 0


@dataclass
class Outgoing:
    assignments: dict[str, Assignment] = field(default_factory=dict)
    merged_delta: MapDelta | None = None
    status: CoordinatorStatus | None = None


class Coordinator(TargetAllocation):
    """The swarm's map and plan. With a ``ReplayPool`` (``agents.replay``), robots'
    merges and corrections are replayed on its worker processes, and ``collect()``
    brings in what they changed; without one, on the calling thread."""

    def __init__(
        self,
        cfg: Config,
        robots: dict[str, tuple[float, float, float]],
        pool: ReplayPool | None = None,
    ) -> None:
        self.cfg = cfg
        self.pool = pool
        self.merger: MergeProcess | None = None  # merging on a process (``use_merger``)
        self._in_merge: tuple[set, MergeJob] | None = None  # the job on its way, its robots
        self._fresh = False  # a merge came in since the last plan
        self._facts: tuple | None = None  # (merged map version, its frontier facts)
        self.merge_lag_ms: list[float] = []  # wall time from sending a merge job to applying it
        self.merger_cpu_ms: list[float] = []  # the merge process's processor time per job
        self.worker_replay_cpu_ms: list[float] = []  # the pool's processor time per update
        self.replay_lag_ms: list[float] = []  # wall time from sending an update to taking it in
        self.strategy = Strategy(cfg.explore.strategy)
        self.robots = {rid: RobotInfo(rid, np.array(p, dtype=float)) for rid, p in robots.items()}
        self.merged = GridPolyMap(cfg.map.cell_size_m)
        self.graph = NavGraph.for_robot(self.merged, cfg.nav)
        self._index: GraphIndex | None = None  # the graph as a matrix, until it changes
        # a wall seen at a grazing angle by one robot (a chord of frontier vectors just
        # behind it) and head-on by another (an obstacle a centimetre in front) is a wall:
        # with the exact union the chord stays the boundary and its frontier never closes
        self._merge_options = MergeOptions(
            obstacle_snap_m=cfg.slam.obstacle_snap_m,
            obstacle_snap_behind_m=cfg.slam.obstacle_snap_behind_m,
            obstacle_snap_front_m=cfg.slam.obstacle_snap_front_m,
        )
        self.sensor = Sensor.of(cfg.sim.lidar)  # the robots' lidar: how far they see
        self.targets: dict[int, Target] = {}
        self._target_cache = TargetCache()  # frontier facts reused while their cells stay
        # target ids differ from those of an earlier run of the coordinator (a restart):
        # robots must not take a new target for the one they already reached
        self._next_id = int(time.time() * 10) % 1_000_000_000
        self.failures: dict[int, float] = {}
        self.looks: dict[int, int] = {}  # target id -> looks from its goal that left it open
        self.blacklist: list[np.ndarray] = []
        # per blacklisted frontier (one per goal, midpoint pair): for one given up after
        # looks, the merged cells' index box around it and their state then; else None
        self._blacklist_looks: list[tuple[tuple[int, int, int, int], tuple[int, int]] | None]
        self._blacklist_looks = []
        self._retried_at_m2 = -math.inf  # explored area at the blacklist's last retry
        self.state = MissionState.STARTING
        self._no_target_since: float | None = None
        self._no_target_cycles = 0
        self._last_cycle = -math.inf
        self._wake = True
        # merge time since the last cycle (counts into the cycle): wall and processor ms
        self._pending_ms = self._pending_cpu_ms = 0.0
        self._timing = False  # inside a ``timed`` block
        self._pending: dict[str, set] = {}  # robot -> its cells changed since the last merge
        self._rebuild: set = set()  # cells a robot's correction changed: merged afresh
        self.corrections = 0  # robot corrections replayed on their map copies
        self._last_flush = -math.inf
        self.cycle_ms: list[float] = []
        self.cycle_cpu_ms: list[float] = []  # this thread's processor time of each cycle
        self.now = 0.0
        self.bytes_sent = 0
        self.replayed_merges = 0  # robot merges replayed on their map copies
        self.replay_cpu_ms: list[float] = []  # this thread's processor time of each replay
        # wall milliseconds of all the work in the coordinator's thread, by stage: replays
        # of robots' merges, cell deltas, full maps, blocking map fetches, merging into the
        # merged map, the cycle's planning, journaling and publishing. All of it counts
        # into the next cycle's time (``cycle_ms``): it delays the cycle as much
        self.stage_ms: dict[str, float] = {}
        self.applied_deltas = 0  # robot cell deltas applied to them
        self.map_fetches = 0  # robot maps fetched whole (a gap, or a merge that differed)
        self.fetch_bytes = 0  # ... and the bytes they took
        self.gaps = 0  # robot map updates that did not apply (lost, late, replayed otherwise)
        self.frames_pending: tuple[str, ...] = ()  # robots exploring in frames of their own
        # robots drawn to a rendezvous (``agents.anchoring``): robot -> (x m, y m, heading
        # rad) in this coordinator's frame. A robot exploring alone is drawn to where its
        # candidate frame puts the nearest robot of the swarm (and the way that one faces)
        self.rendezvous: dict[str, tuple[float, ...]] = {}
        # ... and those of them whose candidate frame the robots were seen at: they tour
        # standpoints before their own frontiers (which the swarm has likely explored)
        self.tour_first: set[str] = set()
        # its robots plan on their own maps, not on this one (a team of robots whose
        # frames are not known yet, ``agents.anchoring``): goals only in a robot's own map
        self.own_maps = False
        self.meetings = Meetings(cfg)  # their tours once no frontier is left
        self.out_of_frontiers = False  # the last cycle found no frontier a robot can reach

    # -- inputs -------------------------------------------------------------------------------

    def robot(self, rid: str) -> RobotInfo:
        info = self.robots.get(rid)
        if info is None:  # a robot not in the config joins at the origin of the map frame
            log.warning("robot %s is not in the config: its start pose is unknown", rid)
            info = self.robots[rid] = RobotInfo(rid, np.zeros(3))
        return info

    def restore(self, merged: GridPolyMap | None, robot_maps: dict[str, GridPolyMap]) -> None:
        """Start from persisted state (a restarted coordinator): the merged map and what
        each robot had shared; the robots' queryables fill in anything newer."""
        if merged is not None:
            if abs(merged.cell_size - self.merged.cell_size) > 1e-9:
                raise MapError("persisted merged map has another cell size than the config")
            self.merged = merged
            self.graph = NavGraph.for_robot(merged, self.cfg.nav)
            self._index = None
            if self.merger is not None:  # a job on its way is dropped: its robots go again
                for rid in self._in_merge[0] if self._in_merge else ():
                    self._pending.setdefault(rid, set()).update(self.robot(rid).map.cells)
                self._in_merge = None
                self.merger.reset(merged)
        for rid, pmap in robot_maps.items():
            self._set_map(self.robot(rid), pmap)
            # cells applied but not merged when the old process died are merged now
            # (cells the merged map already holds are dropped cheaply before the overlay)
            self._pending.setdefault(rid, set()).update(pmap.cells)

    def on_alive(self, rid: str, alive: bool) -> None:
        info = self.robot(rid)
        if info.alive != alive:
            log.info("robot %s %s", rid, "joined" if alive else "left")
            info.alive = alive
            if not alive:
                info.assignment = None
            self._wake = True

    def on_pose(self, rid: str, stamp_s: float, pose: Pose) -> None:
        self.now = max(self.now, stamp_s)
        info = self.robot(rid)
        info.pose = np.array([pose.x, pose.y, pose.theta])
        info.frame = pose.frame
        info.announced = max(info.announced, pose.map_version)
        info.pose_t = max(info.pose_t, stamp_s)
        self._check_behind(info)

    def _check_behind(self, info: RobotInfo) -> None:
        have = 0 if info.map is None else info.map.version
        if info.inflight:  # on its way through the replay pool
            have = max(have, info.queued)
        if info.announced > have:  # a delta is late or lost
            info.behind_since = info.behind_since if info.behind_since is not None else self.now
        else:
            info.behind_since = None

    def needs_resync(self) -> list[str]:
        """Robots whose map the coordinator has been behind for ``RESYNC_AFTER_S``."""
        return [
            r.id
            for r in self.robots.values()
            if r.behind_since is not None and self.now - r.behind_since >= RESYNC_AFTER_S
        ]

    def on_status(self, rid: str, stamp_s: float, status: RobotStatus) -> None:
        self.now = max(self.now, stamp_s)
        info = self.robot(rid)
        old = info.status
        info.status = status
        a = info.assignment
        if a is None or status.target != a.target:
            return
        if old is not None and old.state == status.state and old.target == status.target:
            return
        if status.state in (RobotState.UNREACHABLE, RobotState.STUCK):
            if a.kind == AssignmentKind.HOME:
                info.home_failed = True  # exploring is over; a robot short of home is fine
                log.info("robot %s cannot get home (%s)", rid, status.state)
            else:
                # no path on the map, or a robot that could not get on after recovering
                # (agents.behaviour): it hands the target back, and is not sent there again
                # for a while; repeated, the target is given up. A robot that hardly moved
                # since it last got closer is stuck itself (in clutter, or lost): that says
                # nothing of the target
                stalled = (
                    status.state == RobotState.STUCK
                    and info.pose is not None
                    and info.progress_xy is not None
                    and math.dist(info.progress_xy, info.pose[:2]) < STALLED_M
                )
                self._failed(info, a.target, str(status.state), STALLED_WEIGHT if stalled else 1.0)
        elif (
            status.state == RobotState.REACHED
            and a.kind == AssignmentKind.EXPLORE
            and info.reached_t is None  # the first report counts (looking since then)
        ):
            # judged at the next cycles: a frontier still open after the robot stood
            # there and looked at it counts as a failure of that target
            info.reached_t = stamp_s
        self._wake = True

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

    def spent(self, stage: str, wall_ms: float, cpu_ms: float) -> None:
        """Work done in the coordinator's thread: counted into the next cycle's time."""
        self._pending_ms += wall_ms
        self._pending_cpu_ms += cpu_ms
        self.stage_ms[stage] = self.stage_ms.get(stage, 0.0) + wall_ms

    @contextmanager
    def timed(self, stage: str):
        """``with coord.timed("fetch"): ...`` counts the block as work of ``stage``
        (a block inside another is counted as the outer's)."""
        if self._timing:
            yield
            return
        self._timing = True
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            yield
        finally:
            self._timing = False
            self.spent(stage, (time.perf_counter() - t0) * 1e3, (time.thread_time() - c0) * 1e3)

    def stage_shares(self) -> dict[str, float]:
        """Each stage's share of all the work counted into cycles."""
        total = sum(self.stage_ms.values())
        return {k: v / total for k, v in sorted(self.stage_ms.items())} if total else {}

    # -- the cycle -------------------------------------------------------------------------

    def _awaiting_merge(self) -> bool:
        """A merge is on its way and no newer map than the last plan's is in: planning
        waits for it, as it would for a merge on this thread."""
        return self.merger is not None and self.merger.busy and not self._fresh

    def due(self) -> bool:
        if self._awaiting_merge() and not self.merger.ready():
            return False  # (a result that is in is taken by the cycle's flush)
        return self._wake or self.now - self._last_cycle >= self.cfg.explore.cycle_period_s

    def cycle(self) -> Outgoing:
        out = Outgoing(merged_delta=self.flush(send=True))
        if self._awaiting_merge():
            self._wake = True  # plan on the map the merge process is making
            return out
        self._fresh = False
        t0, c0 = time.perf_counter(), time.thread_time()
        self._last_cycle = self.now
        self._wake = False
        live = [r for r in self.robots.values() if r.alive and r.pose is not None]
        if self.state == MissionState.STARTING and live and self.merged.cells:
            self.state = MissionState.EXPLORING
            log.info("exploring with %s", [r.id for r in live])
        if (
            self.rendezvous
            and self.state in (MissionState.RETURNING, MissionState.DONE)
            and self.meetings.may_tour(self.rendezvous)
        ):
            log.info("drawn to a rendezvous: exploring again")  # a solo robot, to be seen
            self.state = MissionState.EXPLORING
        if self.state in (MissionState.EXPLORING, MissionState.RETURNING) and live:
            # 1. shortest paths from every robot over the navigation graph
            if self._index is None:
                self._index = GraphIndex.build(self.graph)
            reach = Reach.from_robots(
                self.graph, self.merged, [r.pose[:2] for r in live], self._index
            )
            # 2. frontier targets with goal points the robots can reach, and their costs
            targets = self._update_targets(reach)
            ids = list(targets)
            costs = reach.costs([t.goal for t in targets.values()])
            # a target excluded for every robot (failed recently) waits; it is not gone
            reachable = np.isfinite(costs).any(axis=0)
            self.out_of_frontiers = not reachable.any()
            for k, r in enumerate(live):  # targets this robot failed recently
                for j, tid in enumerate(ids):
                    if r.excluded.get(tid, -math.inf) > self.now:
                        costs[k, j] = math.inf
            if self.own_maps and len(live) > 1 and ids:
                # a waiting team's robots plan on their own maps (``agents.anchoring``):
                # each takes the team's frontiers whose goals lie in its own map
                goals = np.array([targets[t].goal for t in ids]).reshape(-1, 2)
                for k, r in enumerate(live):
                    if r.map is not None:
                        costs[k, ~r.map.is_free_many(goals)] = math.inf
            if self.state == MissionState.RETURNING and reachable.any():
                log.info("new frontiers while returning: exploring again")
                self.state = MissionState.EXPLORING
            if self.state == MissionState.EXPLORING:
                # nothing any robot may take now (none left, or those left failed lately),
                # or a robot seen at its candidate frame (``tour_first``): a robot drawn to
                # a rendezvous tours standpoints in sight of it
                idle = not np.isfinite(costs).any() or bool(self.tour_first & set(self.rendezvous))
                if idle and self.rendezvous and self.meetings.orders(self, live, reach):
                    self._no_target_since, self._no_target_cycles = None, 0
                elif not reachable.any():
                    if self._no_target_since is None:
                        self._no_target_since = self.now
                    # every robot's map merged up to what it announced: nothing in flight;
                    # and some robot on the graph (not one at the tip of its first scan)
                    in_flight = any(r.behind_since is not None for r in live)
                    lost = all(s is None for s in reach.sources)
                    self._no_target_cycles += 0 if in_flight or lost else 1
                    if (
                        self.now - self._no_target_since >= self.cfg.explore.end_confirm_s
                        and self._no_target_cycles >= END_CONFIRM_CYCLES
                        and not self._waiting_for_frames()
                        and not self._retry_blacklisted()
                    ):
                        self._end_exploration(live)
                else:
                    self._no_target_since = None
                    self._no_target_cycles = 0
                    # 3. assignment by strategy, keeping current targets unless beaten
                    self._assign(live, ids, targets, costs)
                    # 4. no progress towards a target for too long counts as a failure
                    self._watch_progress(live, ids, costs)
            if self.state == MissionState.RETURNING and all(
                # home, or unable to get there (the exploration itself is complete)
                r.home_failed or (r.status is not None and r.status.state == RobotState.HOME)
                for r in live
                if r.assignment is not None and r.assignment.kind == AssignmentKind.HOME
            ):
                self.state = MissionState.DONE
                log.info("mission done")
        for r in self.robots.values():
            if r.alive and r.assignment is not None and self.now - r.sent_t >= RESEND_S:
                out.assignments[r.id] = r.assignment
        for rid in out.assignments:
            self.robots[rid].sent_t = self.now
        self.spent("plan", (time.perf_counter() - t0) * 1e3, (time.thread_time() - c0) * 1e3)
        ms, cpu_ms = self._pending_ms, self._pending_cpu_ms
        self._pending_ms = self._pending_cpu_ms = 0.0
        self.cycle_ms.append(ms)
        self.cycle_cpu_ms.append(cpu_ms)
        out.status = CoordinatorStatus(
            self.state,
            tuple(sorted(r.id for r in self.robots.values() if r.alive)),
            len(self.targets),
            self.merged.version,
            self.merged.explored_area(),
            ms,
            self.bytes_sent,
            cpu_ms,
            _points_cm([t.goal for t in self.targets.values()]),
            _points_cm(self.blacklist[::2]),  # goals (each is followed by its midpoint)
            self.gaps,
            self.map_fetches,
            self.fetch_bytes,
        )
        return out

    def _waiting_for_frames(self) -> bool:
        """Robots whose frames are not found yet (``frames_pending``, set by the process)
        hold the end of the exploration: their maps are not merged. After
        ``FRAME_WAIT_S`` without targets it ends all the same, and says whose maps stay
        out (on the robots, persisted)."""
        if not self.frames_pending:
            return False
        if self.now - self._no_target_since < FRAME_WAIT_S:
            return True
        log.warning(
            "no frontier left, and the frames of %s were never found: their maps stay out "
            "of the merged map (on the robots, persisted)",
            ", ".join(self.frames_pending),
        )
        return False


def _gap(rid: str, delta: MapDelta) -> MapError:
    return DeltaGapError(f"first delta of {rid} starts at version {delta.base_version}")


# --- the process ---------------------------------------------------------------------------------


def _points_cm(points) -> tuple[tuple[float, float], ...]:
    """At most MAX_STATUS_POINTS points, rounded to centimetres (for views)."""
    return tuple((round(float(p[0]), 2), round(float(p[1]), 2)) for p in points)[:MAX_STATUS_POINTS]
