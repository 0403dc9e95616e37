"""A robot waiting for its frame, with no frontier of its own map it may take (none left,
or those left failed lately), tours standpoints around where its candidate frame puts the
nearest robot of the swarm (the ``rendezvous`` ``agents.anchoring`` gives its solo
coordinator; ``polyswarm.frames.meeting``).

A frame is committed only where the robots saw each other in three distinct places. A
waiting robot is drawn towards the other robot along its frontiers; in the rooms world
(a 30 m lidar explores the flat from the doorways in seconds) the frontiers ran out at
once, the robots stood where they were, saw each other in one or two places and 5 of 10
waiting robots were never merged (touring did not change that
count in 5 launches; standpoints where a sighting can count merged 7 and then 3 of 10
in two runs of the same code: kept because it adds places to be seen in without a cost
measured). Each standpoint is at least
``SEEN_APART_M`` from the ones before, in sight of the predicted robot, which the robot
turns to face (its goal's one frontier point) before it reports the standpoint reached.
A wrong candidate frame puts the other robot where the waiting one finds nobody: the
sightings contradict it, and the next match proposes another.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from polyswarm.config import Config
from polyswarm.frames.meeting import standpoints
from polyswarm.frames.sighting import SEEN_APART_M
from protocols.messages import Assignment, AssignmentKind, RobotState

log = logging.getLogger(__name__)

MEET_MAX_M = 6.0  # a standpoint no farther than this from the other robot (metres)...
MEET_RANGE_SHARE = 0.8  # ...nor than this share of the lidar's range (LDS-01: 2.8 m)
MEET_TIMEOUT_S = 60.0  # simulated seconds a standpoint may take before the next is tried
MEET_CANDIDATES = 40  # the standpoints nearest the other robot whose paths are costed
_OVER = (RobotState.REACHED, RobotState.UNREACHABLE, RobotState.STUCK)


@dataclass
class _Tour:
    visited: list[tuple[float, float]] = field(default_factory=list)  # standpoints so far
    target: int | None = None  # the assignment sent for the current one
    goal: tuple[float, float] = (0.0, 0.0)
    since_s: float = 0.0
    # the rendezvous at which no standpoint was left: tried again once it moves
    exhausted_at: tuple[float, float] | None = None

    def exhausted(self, xy) -> bool:
        at = self.exhausted_at
        return at is not None and math.dist(at, xy) < SEEN_APART_M


class Meetings:
    """The tours of one (solo) coordinator's robots."""

    def __init__(self, cfg: Config) -> None:
        self.reach_m = min(MEET_MAX_M, MEET_RANGE_SHARE * cfg.sim.lidar.range_max_m)
        self.wall_m = cfg.nav.obstacle_clearance_m
        self.fov_rad = cfg.sim.lidar.fov_rad  # the swarm's robots' lidars, as this one's
        self.tours: dict[str, _Tour] = {}

    def may_tour(self, rendezvous: dict[str, tuple[float, ...]]) -> bool:
        """Whether a robot drawn to ``rendezvous`` may have a standpoint left."""
        return any(
            rid not in self.tours or not self.tours[rid].exhausted(at[:2])
            for rid, at in rendezvous.items()
        )

    def orders(self, coord, live, reach) -> bool:
        """Send every robot of ``coord`` with a rendezvous to its next standpoint when it
        is done with the last (``live``: the cycle's robots, ``reach``: their paths over
        ``coord``'s graph). True while one of them tours."""
        touring = False
        for k, r in enumerate(live):
            at = coord.rendezvous.get(r.id)
            if at is None:
                continue
            xy = (float(at[0]), float(at[1]))
            tour = self.tours.setdefault(r.id, _Tour())
            if tour.exhausted(xy):
                continue
            if tour.target is not None:
                a = r.assignment
                if a is not None and a.target == tour.target and not self._over(r, tour, coord):
                    touring = True
                    continue
                tour.visited.append(tour.goal)  # reached, failed or timed out: not again
                tour.target = None
            pts = standpoints(
                coord.merged, at, tour.visited, self.reach_m, self.wall_m, self.fov_rad
            )
            pts = pts[:MEET_CANDIDATES]
            cost = reach.costs([tuple(p) for p in pts])[k] if len(pts) else np.zeros(0)
            if not np.isfinite(cost).any():
                tour.exhausted_at = xy
                log.info("%s: no standpoint left in sight of (%.1f, %.1f)", r.id, *xy)
                continue
            j = int(np.argmin(cost))
            goal = (float(pts[j][0]), float(pts[j][1]))
            r.assignment = Assignment(
                AssignmentKind.EXPLORE,
                coord.new_target_id(),
                goal,
                (xy,),  # the robot turns to face it there
                float(cost[j]),
                coord.merged.version,
            )
            r.reached_t, r.sent_t = None, -math.inf
            tour.target, tour.goal, tour.since_s = r.assignment.target, goal, coord.now
            touring = True
            log.info(
                "%s tours standpoint %d at (%.1f, %.1f), in sight of (%.1f, %.1f)",
                r.id,
                len(tour.visited) + 1,
                *goal,
                *xy,
            )
        return touring

    @staticmethod
    def _over(r, tour: _Tour, coord) -> bool:
        s = r.status
        if s is not None and s.target == tour.target and s.state in _OVER:
            return True
        return coord.now - tour.since_s > MEET_TIMEOUT_S
