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
from agents.merger import MergeJob, MergeProcess
from agents.merging import MergeSchedule
from agents.replay import ReplayPool
from agents.robotmaps import RobotMaps
from polyswarm.config import Config
from polyswarm.errors import MapError
from polyswarm.explore.assign import GraphIndex, Reach, Strategy
from polyswarm.explore.targets import Sensor, Target, TargetCache
from polyswarm.frames.jointgraph import KeyframeLedger
from polyswarm.nav.navgraph import NavGraph
from polyswarm.polymap import GridPolyMap, MapDelta, MergeOptions
from polyswarm.slam.follow import Atlas
from protocols.messages import (
    MAX_STATUS_POINTS,
    Assignment,
    AssignmentKind,
    CoordinatorStatus,
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
# every robot home, the mission waits at most this long (s) for maps it has not received
# yet (a robot back from out of range hands over what it mapped alone: 1-2 s)
HANDOVER_WAIT_S = 20.0
# ... and at most this long (s, from when it left) for a robot that left out of range
# before it was home: cut off, it explores its own frontiers, then drives home, back
# into range (one cut off for 120 s in bench fleet --part cuts)
OUT_OF_RANGE_WAIT_S = 180.0


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
    left_t: float | None = None  # when it left (its liveliness gone) before it was home
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


class Coordinator(RobotMaps, MergeSchedule, TargetAllocation):
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
        self._last_flush = -math.inf
        self.now = 0.0
        self.frames_pending: tuple[str, ...] = ()  # robots exploring in frames of their own
        self._handover_since: float | None = None  # every robot home, waiting for a map
        self._awaited: list[str] = []  # robots out of range the mission end waits for
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
        self._init_counters()

    def _init_counters(self) -> None:
        """What the coordinator counts and times (its metrics and benchmarks read them)."""
        self.merge_lag_ms: list[float] = []  # wall time from sending a merge job to applying it
        self.merger_cpu_ms: list[float] = []  # the merge process's processor time per job
        self.worker_replay_cpu_ms: list[float] = []  # the pool's processor time per update
        self.replay_lag_ms: list[float] = []  # wall time from sending an update to taking it in
        self.corrections = 0  # robot corrections replayed on their map copies
        self.cycle_ms: list[float] = []
        self.cycle_cpu_ms: list[float] = []  # this thread's processor time of each cycle
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
            if alive and info.left_t is not None:  # back from out of range: behind until
                info.behind_since = self.now  # its first pose says which map it has
            info.alive = alive
            home = info.status is not None and info.status.state == RobotState.HOME
            info.left_t = self.now if not alive and not home and info.pose is not None else None
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
            targets, ids, costs, reachable = self._targets_and_costs(live, reach)
            if self.state == MissionState.RETURNING and reachable.any():
                log.info("new frontiers while returning: exploring again")
                self.state = MissionState.EXPLORING
            if self.state == MissionState.EXPLORING:
                self._explore(live, reach, targets, ids, costs, reachable)
            if self.state == MissionState.RETURNING and all(
                # home, or unable to get there (the exploration itself is complete)
                r.home_failed or (r.status is not None and r.status.state == RobotState.HOME)
                for r in live
                if r.assignment is not None and r.assignment.kind == AssignmentKind.HOME
            ):
                self._finish(live)
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
        out.status = self._status(ms, cpu_ms)
        return out

    def _targets_and_costs(self, live, reach):
        """The frontier targets, their ids, each live robot's cost to each (inf where it
        failed it lately, or, in a waiting team, where the goal is outside its own map)
        and which targets some robot may reach."""
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
        return targets, ids, costs, reachable

    def _explore(self, live, reach, targets, ids, costs, reachable) -> None:
        """One cycle of the exploration: rendezvous orders, the end of the exploration
        when no frontier is left (confirmed), or assignment and progress watch."""
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

    def _status(self, ms: float, cpu_ms: float) -> CoordinatorStatus:
        """The status this cycle publishes (its cost ``ms``, ``cpu_ms``)."""
        return CoordinatorStatus(
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

    def _finish(self, live) -> None:
        """Every robot home: the mission is done once every map a robot announced is
        here (one back from out of range first hands over what it mapped alone), or
        after ``HANDOVER_WAIT_S`` of waiting for it; a robot that left before it was home
        holds the end up to ``OUT_OF_RANGE_WAIT_S`` after it left."""
        behind = sorted(r.id for r in live if r.behind_since is not None)
        away = sorted(
            r.id
            for r in self.robots.values()
            if not r.alive and r.left_t is not None and self.now - r.left_t < OUT_OF_RANGE_WAIT_S
        )
        if behind and self._handover_since is None:
            self._handover_since = self.now
        if behind and self.now - self._handover_since < HANDOVER_WAIT_S:
            return
        if away:
            if away != self._awaited:
                log.info("mission end waits for %s, out of range", ", ".join(away))
                self._awaited = away
            return
        gone = sorted(r.id for r in self.robots.values() if not r.alive and r.left_t is not None)
        if behind or gone:
            log.warning("mission done without the last updates of %s", ", ".join(behind + gone))
        self.state = MissionState.DONE
        log.info("mission done")

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


# --- the process ---------------------------------------------------------------------------------


def _points_cm(points) -> tuple[tuple[float, float], ...]:
    """At most MAX_STATUS_POINTS points, rounded to centimetres (for views)."""
    return tuple((round(float(p[0]), 2), round(float(p[1]), 2)) for p in points)[:MAX_STATUS_POINTS]
