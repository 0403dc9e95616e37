"""A robot out of the coordinator's reach explores on its own map.

On a radio that drops, a robot can be cut off for minutes. Standing still at its last
target wastes them. Once no coordinator has been alive for ``ALONE_AFTER_S`` (its
liveliness token gone: the lease ran out) and the robot has nothing left to do, it
picks frontier targets of its own map itself:

- frontiers whose far side the merged map it last had already holds (another robot
  explored there) are left out;
- so are frontiers near where another robot was last seen (``PEER_WARY_M``): that
  robot is likely exploring there, out of reach as well;
- the nearest remaining one it can plan a path to, on its own map (the merged map
  stops growing while it is cut off; its own does not).

Its own targets have ids below -1 (the coordinator's are 0 and up; -1 is stop): a
coordinator that hears its status later ignores them. The first message from a
coordinator ends it: the repeated assignment (every ``RESEND_S``) takes over.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from polyswarm.explore.targets import Sensor, Target, frontier_targets
from polyswarm.nav.navgraph import NavGraph
from polyswarm.polymap import GridPolyMap
from protocols.messages import Assignment, AssignmentKind, RobotState

log = logging.getLogger(__name__)

ALONE_AFTER_S = 5.0  # no coordinator alive this long (simulated or sensor seconds): alone
PEER_WARY_M = 3.0  # frontiers this close to where another robot was last seen are its
BEYOND_M = 0.3  # a frontier's far side, this far past its midpoint: explored by others?
PLAN_TRIES = 5  # nearest targets tried for a path before giving up for now
RETRY_S = 2.0  # alone and idle with no target found: look again this much later
DONE_M = 1.0  # a goal of its own it finished or gave up: not chosen again this close
FIRST_OWN_TARGET = -2  # own target ids count down from here
IDLE_STATES = (RobotState.IDLE, RobotState.REACHED, RobotState.UNREACHABLE, RobotState.STUCK)


@dataclass
class Alone:
    """Whether the robot is on its own, and the targets it chose itself."""

    coordinators: set[str] = field(default_factory=set)  # alive now
    heard_once: bool = False  # a coordinator was alive at some time
    gone_since: float | None = None  # when the last one went
    next_id: int = FIRST_OWN_TARGET
    done: list[np.ndarray] = field(default_factory=list)  # own goals finished or given up
    tried_s: float = -math.inf  # when it last looked for a target

    def coordinator(self, name: str, alive: bool, now_s: float) -> None:
        """A coordinator's liveliness changed."""
        if alive:
            self.coordinators.add(name)
            self.heard_once, self.gone_since = True, None
            return
        self.coordinators.discard(name)
        if not self.coordinators and self.gone_since is None:
            self.gone_since = now_s

    def active(self, now_s: float) -> bool:
        return (
            self.heard_once
            and self.gone_since is not None
            and now_s - self.gone_since >= ALONE_AFTER_S
        )

    def wants_target(self, now_s: float, state: RobotState, current: Assignment | None) -> bool:
        """Alone, with nothing to do: no assignment, told to wait (a stop: no target left
        for it then), or an exploration target finished or given up; the way home the
        coordinator sent at the mission's end stands."""
        if not self.active(now_s) or state not in IDLE_STATES:
            return False
        return current is None or current.kind != AssignmentKind.HOME

    def due(self, now_s: float) -> bool:
        """Time to look for a target (at most every ``RETRY_S``)."""
        if now_s - self.tried_s < RETRY_S:
            return False
        self.tried_s = now_s
        return True

    def choose(
        self,
        own: GridPolyMap,
        graph: NavGraph,
        merged: GridPolyMap | None,
        sensor: Sensor,
        xy: np.ndarray,
        peers_xy: list[np.ndarray],
        plan,
        current: Assignment | None,
    ) -> Assignment | None:
        """The nearest frontier target of ``own`` left to this robot that ``plan(goal)``
        finds a path to; None when there is none."""
        if current is not None and current.target <= FIRST_OWN_TARGET:
            self.done.append(np.array(current.goal, dtype=float))  # looked at, or given up
        targets = frontier_targets(
            own, graph, blacklist=peers_xy, blacklist_radius_m=PEER_WARY_M, sensor=sensor
        )
        targets = [
            t
            for t in targets
            if not _explored_beyond(t, merged)
            and all(math.dist(t.goal, g) >= DONE_M for g in self.done)
        ]
        targets.sort(key=lambda t: math.dist(t.goal, xy))
        for t in targets[:PLAN_TRIES]:
            if plan(t.goal) is None:
                self.done.append(np.asarray(t.goal, dtype=float))
                continue
            a = Assignment(
                AssignmentKind.EXPLORE,
                self.next_id,
                tuple(map(float, t.goal)),
                tuple(tuple(map(float, p)) for p in t.frontier.points),
            )
            self.next_id -= 1
            log.info("alone: own target %d at (%.1f, %.1f)", a.target, *a.goal)
            return a
        return None


def _explored_beyond(t: Target, merged: GridPolyMap | None) -> bool:
    """Whether the merged map already holds the unexplored side of ``t``'s frontier (free
    space is on a frontier vector's left: its far side is on the right)."""
    if merged is None:
        return False
    d = t.frontier.end - t.frontier.start
    n = np.hypot(*d)
    if n == 0:
        return False
    right = np.array([d[1], -d[0]]) / n
    return merged.is_free(*(t.midpoint + BEYOND_M * right))
