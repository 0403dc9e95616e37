"""Target allocation, the coordinator's third job: frontier targets of the merged map,
their path costs from every robot, the assignment by strategy with hysteresis, failures
and blacklisting, looks at frontiers that stay open, and the mission's end.

``TargetAllocation`` is a part of ``agents.coordinator.Coordinator`` (it uses its state:
the robots, the merged map and its graph, the targets)."""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np

from polyswarm.explore.assign import Reach, assign, target_groups
from polyswarm.explore.targets import Target, frontier_targets
from polyswarm.nav.navgraph import clear_of
from polyswarm.polymap import VectorType
from protocols.messages import (
    Assignment,
    AssignmentKind,
    MissionState,
)

log = logging.getLogger(__name__)


if TYPE_CHECKING:
    from agents.coordinator import RobotInfo

MATCH_M = 1.0  # a target within this of last cycle's keeps its id
PROGRESS_M = 0.5  # progress towards a target: its path cost shrank by this much
EXCLUDE_S = 30.0  # a robot that failed a target is not sent there again for this long
GOAL_MOVED_M = 0.5  # a kept target whose goal moved this far is sent again
GOAL_RESET_M = 2.0  # ... and if this far, progress towards it is measured afresh
STALLED_M = 1.0  # a robot that moved less than this while making no progress is stuck itself
# a robot the assignment left over this long follows to its nearest target, taken by
# another robot. Following at once made the office slower (known starts, 5 seeds side
# by side: t99 median 80 to 89 s), where robots left over were parked 10-20 s; in
# the maze at unknown starts two robots stood 100-120 s while a third explored the last
# wing alone (parked robot-seconds before t99: examples/trajectory_speeds.py)
FOLLOW_AFTER_S = 20.0
# ... which is weak evidence against its target: it counts this much of a failure (not
# nothing: three robots wedged in turn at the same narrow way retried it for 2,000 s)
STALLED_WEIGHT = 0.5
REACHED_GRACE_S = 2.0  # a reached target's frontier may take this long to leave the map
# a robot drawn to a rendezvous counts a goal's distance from it this many times on top of
# its path cost: equal weight sends it along the frontiers that lead there
RENDEZVOUS_WEIGHT = 1.0
# after a look, a frontier point farther than this from every frontier vector has moved
# on (the view opened the space behind it); the look failed if most (LOOK_OPEN_SHARE)
# of the frontier's points did not. A TurtleBot3 at a door sees 3.5 m into the room: the
# frontier moves on, and judging by the target's id (a frontier near the same goal) ten
# frontiers were blacklisted after one look each and the mission ended at 29 %
LOOK_MOVED_M = 0.25
LOOK_OPEN_SHARE = 0.5
# before the exploration ends, the blacklisted frontiers get one more round if the
# explored area grew by this much since their last round (or never had one): a failure
# may have been the map's of its time, not the frontier's. Two TurtleBot3 office runs
# ended at 77 % and 90 % after one frontier each failed twice; each round must be paid
# for by new explored space, so rounds cannot repeat for ever
RETRY_GROWTH_M2 = 2.0
# ... except a frontier that a look left open (the robot stood within sensor range) and
# whose merged cells within this (m) have not changed since it was given up: a new look
# would see the same map. With the TurtleBot3's odometry noise, single-robot loop runs
# at 98 % drove back to wall frontiers that two looks had left open (a wall placed off
# by the pose error), and 99 % came only on the way home (3.2 and 3.3 times the
# reference). Measured since: it decided differently in 2 of 20 such runs, and no effect
# beyond run-to-run spread is shown
LOOK_RETRY_MARGIN_M = LOOK_MOVED_M + 1.0


class TargetAllocation:
    """The coordinator's methods that choose and assign targets (see the module)."""

    def _update_targets(self, reach: Reach) -> dict[int, Target]:
        e = self.cfg.explore
        found = frontier_targets(
            self.merged,
            self.graph,
            e.min_frontier_length_m,
            e.max_frontier_length_m,
            0.0,
            self.blacklist,
            reach=reach,
            cache=self._target_cache,
            sensor=self.sensor,
            facts=self._facts[1] if self._facts and self._facts[0] == self.merged.version else None,
        )
        # keep ids: a target near last cycle's is the same target
        old_ids = list(self.targets)
        old_goals = np.array([o.goal for o in self.targets.values()]).reshape(-1, 2)
        old_mids = np.array([o.midpoint for o in self.targets.values()]).reshape(-1, 2)
        taken = np.zeros(len(old_ids), dtype=bool)
        new: dict[int, Target] = {}
        for t in found:
            tid = None
            near = ~taken & (
                (np.hypot(*(old_goals - t.goal).T) < MATCH_M)
                | (np.hypot(*(old_mids - t.midpoint).T) < MATCH_M)
            )
            if near.any():
                k = int(np.argmax(near))
                taken[k] = True
                tid = old_ids[k]
            if tid is None:
                tid = self._next_id
                self._next_id += 1
            new[tid] = t
        self.targets = new
        return new

    def _assign(self, live, ids, targets, costs) -> None:
        current = []
        for r in live:
            a = r.assignment
            cur = ids.index(a.target) if a is not None and a.target in targets else None
            current.append(cur)
        utilities = [targets[t].utility_m for t in ids]
        goals = np.array([targets[t].goal for t in ids]).reshape(-1, 2)
        choice = assign(
            self.strategy,
            self._drawn(costs, goals, live),
            utilities,
            current,
            self.cfg.explore.hysteresis,
            goals,
            self.cfg.explore.target_separation_m,
            target_groups(
                [targets[t].frontier.chain for t in ids],
                goals,
                self.cfg.explore.target_separation_m,
            ),
            [self._follows(r) for r in live],
        )
        self._note_left_over(live, choice)
        for k, (r, j) in enumerate(zip(live, choice, strict=True)):
            if j is None:
                if r.assignment is not None and r.assignment.kind == AssignmentKind.EXPLORE:
                    r.assignment = Assignment(AssignmentKind.STOP, -1)
                    r.sent_t = -math.inf
                continue
            tid = ids[j]
            t = targets[tid]
            moved = (
                r.assignment is not None
                and r.assignment.target == tid
                and np.hypot(*(np.array(r.assignment.goal) - t.goal)) > GOAL_MOVED_M
            )
            new = r.assignment is None or r.assignment.target != tid
            if new:
                r.best_cost, r.progress_t = math.inf, self.now
            if new or moved:  # a new target, or the frontier moved as the map grew
                r.reached_t = None
                r.sent_t = -math.inf
                r.assignment = Assignment(
                    AssignmentKind.EXPLORE,
                    tid,
                    (float(t.goal[0]), float(t.goal[1])),
                    tuple((float(x), float(y)) for x, y in t.frontier.points[:64]),
                    float(costs[k, j]),
                    self.merged.version,
                )

    def _follows(self, r: RobotInfo) -> bool:
        """Left over by the assignment for ``FOLLOW_AFTER_S``: it may follow another."""
        return r.left_over_since is not None and self.now - r.left_over_since >= FOLLOW_AFTER_S

    def _note_left_over(self, live, choice: list[int | None]) -> None:
        """Since when each robot was left over by the assignment: a robot without a
        target, or one sharing its target while it was left over (it follows), stays
        so; one with a target of its own is not."""
        shared = {j for j in choice if j is not None and choice.count(j) > 1}
        for r, j in zip(live, choice, strict=True):
            if j is None and r.left_over_since is None:
                r.left_over_since = self.now
            elif j is not None and j not in shared:
                r.left_over_since = None

    def _drawn(self, costs: np.ndarray, goals: np.ndarray, live) -> np.ndarray:
        """Path costs (metres, robots x targets), plus for a robot with a ``rendezvous``
        each goal's (targets x 2) distance to it: the robot explores towards it."""
        if not self.rendezvous:
            return costs
        out = costs.copy()
        for k, r in enumerate(live):
            at = self.rendezvous.get(r.id)
            if at is not None:
                out[k] += RENDEZVOUS_WEIGHT * np.hypot(*(goals - at[:2]).T)
        return out

    def _watch_progress(self, live, ids, costs) -> None:
        timeout = self.cfg.explore.no_progress_timeout_s
        for k, r in enumerate(live):
            a = r.assignment
            if a is None or a.kind != AssignmentKind.EXPLORE or a.target not in ids:
                continue
            if self._looked(r):
                r.reached_t = None
                if not self._look_failed(r, a):
                    # what it saw moved the frontier on (a short-range lidar sees a room a
                    # few metres at a time): no failure, a new target at the next cycle
                    r.assignment = None
                    self._wake = True
                    continue
                # the robot looked from within sensor range, and the frontier is still
                # open where it was: a failure, and after explore.blacklist_after_looks
                # such looks given up
                n = self.looks[a.target] = self.looks.get(a.target, 0) + 1
                t = self.targets.get(a.target)
                self._failed(r, a.target, "reached, frontier still open")
                given_up = t is None or any(np.array_equal(b, t.goal) for b in self.blacklist)
                if n >= self.cfg.explore.blacklist_after_looks and not given_up:
                    self._blacklist(t, f"looked at {n} time(s), still open", looked=True)
                continue
            c = costs[k, ids.index(a.target)]
            # a frontier that retreats as the robot drives (down a long corridor) moves
            # its goal: the cost to the new goal is a new baseline, not a lack of progress
            moved = (
                r.progress_goal is not None and math.dist(r.progress_goal, a.goal) > GOAL_RESET_M
            )
            if c < r.best_cost - PROGRESS_M or moved:
                r.best_cost, r.progress_t, r.progress_goal = c, self.now, a.goal
                r.progress_xy = r.pose[:2].copy()
            elif self.now - r.progress_t > timeout:
                # a robot that hardly moved is stuck itself (wedged, or its way blocked):
                # that says nothing of the target, which stays open to the others
                stalled = (
                    r.progress_xy is not None and math.dist(r.progress_xy, r.pose[:2]) < STALLED_M
                )
                why = "robot stalled" if stalled else "no progress"
                weight = STALLED_WEIGHT if stalled else 1.0
                self._failed(r, a.target, f"{why} for {timeout:.0f} s", weight)

    def _looked(self, r: RobotInfo) -> bool:
        """Has the robot looked at its reached target long enough, and has what it saw
        reached the merged map? (judged on the robot's own clock: a lagging coordinator
        must not blame a target for a view it has not merged yet)"""
        if r.reached_t is None or r.pose_t - r.reached_t < REACHED_GRACE_S:
            return False
        return r.map is not None and r.map.version >= r.announced and not self._unmerged(r.id)

    def _look_failed(self, r: RobotInfo, a: Assignment) -> bool:
        """Did the robot look at its frontier from within sensor range and leave it open
        where it was (most of its points still on a frontier of the merged map)?"""
        pts = np.array(a.frontier, dtype=float).reshape(-1, 2)
        if len(pts) == 0:
            return True
        mid = pts[len(pts) // 2]
        if r.pose is None or math.dist(r.pose[:2], mid) > self.sensor.range_m:
            return False  # not a look the frontier can be blamed for
        cells = {
            c
            for p in pts[:: max(1, len(pts) // 8)]
            for c in self.merged.cells_within(p[0], p[1], LOOK_MOVED_M + 1.0)
        }
        st, en, _ = self.merged.vectors([VectorType.FRONTIER], cells)
        still = ~clear_of(pts, st, en, LOOK_MOVED_M)
        return bool(still.mean() >= LOOK_OPEN_SHARE)

    def _failed(self, r: RobotInfo, tid: int, why: str, weight: float = 1.0) -> None:
        """``weight``: how much of a failure this counts towards blacklisting the target."""
        n = self.failures.get(tid, 0.0) + weight
        self.failures[tid] = n
        log.info("target %d failed by %s (%s), %.1f time(s)", tid, r.id, why, n)
        r.excluded[tid] = self.now + EXCLUDE_S
        r.best_cost, r.progress_t = math.inf, self.now
        r.assignment = None
        t = self.targets.get(tid)
        if t is not None and n >= self.cfg.explore.blacklist_after_failures:
            self._blacklist(t, f"failed {n:.1f} times", looked=self.looks.get(tid, 0) > 0)
        self._wake = True

    def _blacklist(self, t: Target, why: str, looked: bool = False) -> None:
        """``looked``: a look left it open; retried only once its cells change."""
        log.info("blacklisting the frontier at (%.1f, %.1f): %s", *t.midpoint, why)
        self.blacklist.append(np.array(t.goal))
        self.blacklist.append(np.array(t.midpoint))
        box = self._look_box(t) if looked else None
        self._blacklist_looks.append(None if box is None else (box, self.merged.box_state(*box)))
        for r in self.robots.values():
            if r.assignment is not None and self.targets.get(r.assignment.target) is t:
                r.assignment = None
        self._wake = True

    def _look_box(self, t: Target) -> tuple[int, int, int, int]:
        """The merged map's cell-index box within ``LOOK_RETRY_MARGIN_M`` of the
        target's frontier: what a look at it depends on."""
        pts = np.asarray(t.frontier.points, dtype=float).reshape(-1, 2)
        if len(pts) == 0:
            pts = np.array([t.midpoint], dtype=float)
        s = self.merged.cell_size
        lo = np.floor((pts.min(axis=0) - LOOK_RETRY_MARGIN_M) / s).astype(int)
        hi = np.floor((pts.max(axis=0) + LOOK_RETRY_MARGIN_M) / s).astype(int)
        return int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1])

    def _retry_blacklisted(self) -> bool:
        """No frontier left but blacklisted ones: give them one more round (failure
        counts and looks start afresh), if the explored area grew by ``RETRY_GROWTH_M2``
        since their last round. A frontier given up after looks stays out while its
        cells are unchanged. True if any got a round."""
        area = self.merged.explored_area()
        if not self.blacklist or area < self._retried_at_m2 + RETRY_GROWTH_M2:
            return False
        stays = [
            k is not None and self.merged.box_state(*k[0]) == k[1] for k in self._blacklist_looks
        ]
        if all(stays):
            log.info(
                "no frontier left but %d blacklisted after looks, with no change near them "
                "since: no more rounds",
                len(stays),
            )
            return False
        log.info(
            "no frontier left but %d blacklisted: %d get one more round (%d looked at, "
            "unchanged near them since, stay out)",
            len(stays),
            stays.count(False),
            stays.count(True),
        )
        self._retried_at_m2 = area
        self.blacklist = [
            p for k, keep in enumerate(stays) if keep for p in self.blacklist[2 * k : 2 * k + 2]
        ]
        self._blacklist_looks = [
            b for b, keep in zip(self._blacklist_looks, stays, strict=True) if keep
        ]
        self.failures, self.looks = {}, {}
        self._no_target_since, self._no_target_cycles = None, 0
        self._wake = True
        return True

    def adopt(self, assignments: dict, max_target: int) -> None:
        """Take the fleet over from another coordinator (``agents.leadership``): its last
        ``assignments`` (robot -> Assignment) become this one's, so that no robot loses
        its target and none is given twice; this one's targets near them take their ids,
        the others new ids above every id heard (``max_target``)."""
        start = max(self._next_id, max_target + 1)
        self.targets = {start + k: t for k, t in enumerate(self.targets.values())}
        self._next_id = start + len(self.targets)
        for r in self.robots.values():
            r.assignment = None
        for rid, a in assignments.items():
            r = self.robot(rid)
            r.assignment, r.sent_t = a, -math.inf  # sent again at once, by the new leader
            r.best_cost, r.progress_t, r.reached_t = math.inf, self.now, None
            if a.kind != AssignmentKind.EXPLORE:
                continue
            near = [
                tid
                for tid, t in self.targets.items()
                if tid >= start and np.hypot(*(t.goal - np.array(a.goal))) < MATCH_M
            ]
            if near:
                self.targets[a.target] = self.targets.pop(near[0])
        self._wake = True

    def new_target_id(self) -> int:
        """A target id not used before in this mission."""
        self._next_id += 1
        return self._next_id - 1

    def _end_exploration(self, live) -> None:
        self.targets = {}
        self._no_target_since, self._no_target_cycles = None, 0
        if not self.cfg.explore.return_home:
            self.state = MissionState.DONE
            log.info("no reachable frontier left: mission done")
            return
        self.state = MissionState.RETURNING
        log.info("no reachable frontier left: robots return to their start")
        for r in live:
            r.home_failed = False
            r.assignment = Assignment(
                AssignmentKind.HOME,
                self._next_id,
                (float(r.start[0]), float(r.start[1])),
                (),
                0.0,
                self.merged.version,
            )
            self._next_id += 1
            r.sent_t = -math.inf
