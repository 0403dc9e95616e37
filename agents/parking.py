"""Idle robots of the merged swarm move out of passages while robots whose frames are
not found yet hold the end of the exploration (``polyswarm.parking``).

Each cycle with no frontier any robot may take, a robot with nothing to do (no order,
stopped, or its last order over) that stands closer than ``park_clearance_m`` to a wall
is sent to the nearest spot (by path over the coordinator's graph) that is not; it faces
nothing there. A robot that could not get to one is not sent again until it has moved
``SEEN_APART_M``.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from polyswarm.config import Config
from polyswarm.parking import blocks_passage, park_clearance_m, parking_spots
from polyswarm.sighting import SEEN_APART_M
from protocols.messages import Assignment, AssignmentKind, RobotState

log = logging.getLogger(__name__)

PARK_CANDIDATES = 40  # the spots nearest the robot whose paths are costed
_DONE = (RobotState.IDLE, RobotState.REACHED, RobotState.UNREACHABLE, RobotState.STUCK)


class Parking:
    def __init__(self, cfg: Config) -> None:
        self.clear_m = park_clearance_m(cfg.nav)
        self.orders_sent: dict[str, int] = {}  # robot -> its parking order's target id
        self.failed_at: dict[str, tuple[float, float]] = {}  # robot -> where it gave up

    def orders(self, coord, live, reach) -> bool:
        """Send the idle robots of ``coord`` that stand in a passage to a spot clear of it
        (``live``: the cycle's robots, ``reach``: their paths over ``coord``'s graph).
        True if an order was sent."""
        sent = False
        for k, r in enumerate(live):
            if not self._idle(r):
                continue
            xy = (float(r.pose[0]), float(r.pose[1]))
            at = self.failed_at.get(r.id)
            if at is not None and math.dist(at, xy) < SEEN_APART_M:
                continue
            if not blocks_passage(coord.merged, xy, self.clear_m):
                continue
            pts = parking_spots(coord.merged, xy, self.clear_m)[:PARK_CANDIDATES]
            cost = reach.costs([tuple(p) for p in pts])[k] if len(pts) else np.zeros(0)
            if not np.isfinite(cost).any():
                self.failed_at[r.id] = xy
                log.info("%s stands in a passage at (%.1f, %.1f), no spot to wait in", r.id, *xy)
                continue
            j = int(np.argmin(cost))
            goal = (float(pts[j][0]), float(pts[j][1]))
            r.assignment = Assignment(
                AssignmentKind.EXPLORE,
                coord.new_target_id(),
                goal,
                (),
                float(cost[j]),
                coord.merged.version,
            )
            r.reached_t, r.sent_t = None, -math.inf
            self.orders_sent[r.id] = r.assignment.target
            sent = True
            log.info(
                "%s waits out of the passage at (%.1f, %.1f): %.1f m from (%.1f, %.1f)",
                r.id,
                *goal,
                cost[j],
                *xy,
            )
        return sent

    def _idle(self, r) -> bool:
        """Nothing to do: no order, a stop, or its order over. A parking order that
        failed (the coordinator drops the order then) is remembered where it failed."""
        a, s = r.assignment, r.status
        if (
            s is not None
            and s.target == self.orders_sent.get(r.id)
            and s.state in (RobotState.UNREACHABLE, RobotState.STUCK)
        ):
            self.failed_at[r.id] = (float(r.pose[0]), float(r.pose[1]))
        if a is None or a.kind == AssignmentKind.STOP:
            return True
        return s is not None and s.target == a.target and s.state in _DONE
