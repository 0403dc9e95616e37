"""The robot's behaviour: a small, named state machine beside the SLAM step.

Every scan, ``Behaviour.step`` takes where the robot is (the SLAM pose), what its lidar
sees now and the time, and returns the velocity command; the state it reports to the
coordinator follows from its mode.

    START_TURN   turn in place once at the start: a lidar with a blind wedge behind
                 (270 degrees) leaves the robot at the tip of its first map otherwise
    IDLE         nothing to do (no assignment, or told to stop)
    NAVIGATE     follow a planned path to the goal, replanned as the map grows;
                 no progress -> RECOVER; blocked by another robot -> YIELD;
                 no path for a while -> UNREACHABLE; there -> LOOK, REACHED or HOME
    LOOK         at an exploration goal: turn to face the frontier, then REACHED
    REACHED      looked at the frontier; waiting for the next order
    HOME         back at the start after the mission
    RECOVER      stuck: drive back along its own trail (the way it came is free), then
                 NAVIGATE again; after MAX_RECOVERIES for one target -> STUCK
    STUCK        the target is handed back: the coordinator gives another one
    YIELD        giving way to another robot that blocks it, then NAVIGATE again
    UNREACHABLE  no path to the goal on the map: told to the coordinator

The behaviour knows nothing of maps: its ``Planning`` (the agent) plans paths, finds a
place to step aside to, and puts the view at a goal into the map.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from enum import StrEnum
from typing import Protocol

import numpy as np

from polyswarm.errors import OffMapError, PlanningError
from polyswarm.nav.control import Follow, PathFollower
from protocols.messages import Assignment, AssignmentKind, RobotState

log = logging.getLogger(__name__)

REPLAN_PERIOD_S = 2.0  # a path is replanned this often as the map grows (sim seconds)
PLAN_RETRY_S = 0.5  # ... and retried this often while planning fails
UNREACHABLE_AFTER_S = 3.0  # planning must fail this long before a goal is unreachable
STUCK_TIMEOUT_S = 8.0  # no progress along the path for this long: recover
PROGRESS_M = 0.2  # ... progress means the remaining path shrank by this much
BLOCKED_RECOVER_S = 4.0  # blocked with no other robot near for this long: recover sooner
# recovery: back along the robot's own trail (where it came from is free, whatever its
# pose error; a TurtleBot4 pressed against a door jamb by 10 cm of error crept and backed
# off for 130 s), for at most RECOVER_S
RECOVER_BACK_M = 0.7
RECOVER_S = 8.0
MAX_RECOVERIES = 2  # recoveries for one target before it is handed back
TRAIL_STEP_M = 0.1  # the trail keeps a point every this far ...
TRAIL_POINTS = 60  # ... this many of them
FACING_RAD = 0.3  # at the goal, turn until the frontier is this close to straight ahead
START_TURN_MAX_S = 10.0  # the start turn ends after this long whatever the odometry says
START_TURN_MARGIN_RAD = 0.3  # the start turn covers the blind wedge and this much more
DEADLOCK_S = 2.0  # blocked this long next to another robot: the lower priority gives way
YIELD_S = 6.0  # ... driving about a metre away for at most this long
PEER_NEAR_M = 1.5
PEER_FRESH_S = 2.0


class Mode(StrEnum):
    START_TURN = "start turn"
    IDLE = "idle"
    NAVIGATE = "navigate"
    LOOK = "look"
    REACHED = "reached"
    HOME = "home"
    RECOVER = "recover"
    STUCK = "stuck"
    YIELD = "yield"
    UNREACHABLE = "unreachable"


WIRE_STATE = {  # what the coordinator is told (protocols RobotState)
    Mode.IDLE: RobotState.IDLE,
    Mode.NAVIGATE: RobotState.NAVIGATING,
    Mode.LOOK: RobotState.NAVIGATING,
    Mode.REACHED: RobotState.REACHED,
    Mode.HOME: RobotState.HOME,
    Mode.RECOVER: RobotState.NAVIGATING,
    Mode.STUCK: RobotState.STUCK,
    Mode.YIELD: RobotState.NAVIGATING,
    Mode.UNREACHABLE: RobotState.UNREACHABLE,
}


class Planning(Protocol):
    """What the behaviour asks of the agent."""

    def plan(self, start: np.ndarray, goal: np.ndarray, partial: bool):
        """A path (``polyswarm.nav.planner.Path``) or ``PlanningError``."""

    def yield_point(self, xy: np.ndarray, other: np.ndarray) -> np.ndarray | None:
        """A free point about a metre from ``xy``, away from ``other``."""

    def look_done(self) -> None:
        """The robot faces the frontier at its goal: put what it sees into the map."""


class Behaviour:
    def __init__(
        self,
        robot_id: str,
        follower: PathFollower,
        planning: Planning,
        max_w_radps: float,
        fov_rad: float,
    ) -> None:
        self.id = robot_id
        self.follower = follower
        self.planning = planning
        self.max_w = max_w_radps
        self.mode = Mode.START_TURN
        self.detail = ""
        self.changed = True  # the reported state changed since the caller last looked
        self.assignment: Assignment | None = None
        self.plans = self.plan_failures = 0
        self.blocked_by = ""  # the robot in our way, told to it with our pose
        self.peers: dict[str, tuple[float, np.ndarray]] = {}  # other robots: (stamp, xy)
        blind = 2 * math.pi - fov_rad  # the wedge behind the lidar (0 for a full circle)
        self._turn_left = min(math.pi, blind + START_TURN_MARGIN_RAD) if blind > 1e-3 else 0.0
        self._turn_until: float | None = None
        self._last_plan = -math.inf
        self._fail_since: float | None = None
        self._nav_gave_up = False  # the robot's Nav2 aborted the goal
        self._best_remaining = math.inf
        self._progress_t = 0.0
        self._blocked_since: float | None = None
        self._until = math.inf  # end of a recovery or a yield
        self._recoveries: dict[int, int] = {}  # target -> recoveries in this assignment
        self._trail: deque = deque(maxlen=TRAIL_POINTS)
        if self._turn_left <= 0:
            self.mode = Mode.IDLE

    def move_frame(self, frame) -> None:
        """The map frame moved (an anchor put the robot into the shared frame): the trail
        it recovers along moves with it, peers seen in the old frame are forgotten."""
        c, s = math.cos(frame[2]), math.sin(frame[2])
        self._trail = deque(
            ((frame[0] + c * x - s * y, frame[1] + s * x + c * y) for x, y in self._trail),
            maxlen=TRAIL_POINTS,
        )
        self.peers.clear()

    # -- inputs ---------------------------------------------------------------------------

    @property
    def state(self) -> RobotState:
        if self.mode == Mode.START_TURN:
            return RobotState.IDLE if self.assignment is None else RobotState.NAVIGATING
        return WIRE_STATE[self.mode]

    def on_assignment(self, a: Assignment, now: float, pose) -> None:
        same = (
            self.assignment is not None
            and a.target == self.assignment.target
            and a.kind == self.assignment.kind
            and a.goal == self.assignment.goal
        )
        self.assignment = a
        if same:
            return
        log.info("%s: assignment %s %d at (%.1f, %.1f)", self.id, a.kind, a.target, *a.goal)
        self.follower.set_path(None)
        self._fail_since = None
        self._nav_gave_up = False
        self._recoveries.clear()  # counted per assignment: given again later, tried again
        if self.mode == Mode.START_TURN:
            return  # planned once the turn is done
        if a.kind == AssignmentKind.STOP:
            self._set(Mode.IDLE, "stopped by the coordinator")
            return
        self._set(Mode.NAVIGATE)
        self._plan(now, pose)

    def on_nav_result(self, reached: bool, why: str) -> None:
        """The robot's own navigation stack (Nav2) reached the goal, or gave up on it."""
        if self.assignment is None or self.mode not in (Mode.NAVIGATE, Mode.RECOVER, Mode.YIELD):
            return
        if reached:
            self._arrived()
        else:
            self.follower.set_path(None)
            self._nav_gave_up = True  # no replanning brings it back: Nav2 tried
            self._set(Mode.UNREACHABLE, why)

    def on_peer(self, rid: str, now: float, xy: np.ndarray, blocked_by: str, pose) -> None:
        self.peers[rid] = (now, np.asarray(xy, dtype=float))
        if blocked_by == self.id and self.mode == Mode.NAVIGATE:
            # I stand in its way: give way, unless we block each other and I go first
            mutual = self.blocked_by == rid and priority(self.id) < priority(rid)
            if not mutual:
                self._give_way(rid, self.peers[rid][1], now, pose)

    # -- the step -------------------------------------------------------------------------

    def step(self, now: float, pose, scan_xy: np.ndarray, moving: np.ndarray, turned: float):
        """The command (v m/s, w rad/s) for this scan; ``scan_xy`` are the lidar's points
        in the robot frame, ``moving`` flags those the map does not explain, ``turned``
        is the rotation since the last scan (radians)."""
        pose = np.asarray(pose, dtype=float)
        if self.mode != Mode.RECOVER:  # going back uses up the trail; it records nothing
            self._record_trail(pose)
        if self.mode == Mode.START_TURN:
            return self._start_turn(now, pose, turned)
        if self.mode == Mode.LOOK:
            return self._look(pose)
        if self.mode in (Mode.RECOVER, Mode.YIELD):
            return self._detour(now, pose, scan_xy, moving)
        if self.mode in (Mode.NAVIGATE, Mode.UNREACHABLE):
            return self._navigate(now, pose, scan_xy, moving)
        return (0.0, 0.0)

    def _start_turn(self, now: float, pose, turned: float):
        if self._turn_until is None:
            self._turn_until = now + START_TURN_MAX_S
        self._turn_left -= abs(turned)
        if self._turn_left > 0 and now < self._turn_until:
            return (0.0, 0.8 * self.max_w)
        a = self.assignment
        if a is None or a.kind == AssignmentKind.STOP:
            self._set(Mode.IDLE)
        else:
            self._set(Mode.NAVIGATE)
            self._plan(now, pose)
        return (0.0, 0.0)

    def _navigate(self, now: float, pose, scan_xy, moving):
        if self._nav_gave_up:
            return (0.0, 0.0)
        due = now - self._last_plan >= REPLAN_PERIOD_S
        retry = self.follower.path is None and now - self._last_plan >= PLAN_RETRY_S
        if due or retry:
            self._plan(now, pose)
        if self.mode != Mode.NAVIGATE or self.follower.path is None:
            return (0.0, 0.0)
        cmd = self.follower.command(pose, scan_xy, moving)
        if cmd.state == Follow.ARRIVED:
            self._arrived()
            return (0.0, 0.0)
        self._watch(now, pose, cmd.state)
        return (cmd.v_mps, cmd.w_radps) if self.mode == Mode.NAVIGATE else (0.0, 0.0)

    def _arrived(self) -> None:
        self.follower.set_path(None)
        a = self.assignment
        if a.kind == AssignmentKind.HOME:
            self._set(Mode.HOME)
        elif a.frontier:
            self._set(Mode.LOOK)  # look at the frontier before reporting
        else:
            self._set(Mode.REACHED)

    def _look(self, pose):
        """Turn in place towards the assigned frontier; then report it reached."""
        pts = np.array(self.assignment.frontier)
        mid = pts[len(pts) // 2] if len(pts) > 2 else pts.mean(axis=0)
        bearing = math.remainder(
            math.atan2(mid[1] - pose[1], mid[0] - pose[0]) - pose[2], 2 * math.pi
        )
        if abs(bearing) <= FACING_RAD:
            self.planning.look_done()
            self._set(Mode.REACHED)
            return (0.0, 0.0)
        return (0.0, math.copysign(min(self.max_w, 2.0 * abs(bearing)), bearing))

    def _watch(self, now: float, pose, follow: Follow) -> None:
        """Progress along the path; blocked by a robot: give way; stuck: recover."""
        remaining = self.follower.remaining_m(pose)
        if remaining < self._best_remaining - PROGRESS_M:
            self._best_remaining, self._progress_t = remaining, now
        if follow != Follow.BLOCKED:
            self._blocked_since, self.blocked_by = None, ""
        elif self._blocked_since is None:
            self._blocked_since = now
        blocked_s = 0.0 if self._blocked_since is None else now - self._blocked_since
        peer = self._nearest_peer(now, pose)
        if blocked_s >= DEADLOCK_S and peer is not None:
            self.blocked_by = peer[0]  # told to it with our pose: it may give way
            if priority(self.id) > priority(peer[0]):
                self._give_way(peer[0], peer[1], now, pose)
            return
        if now - self._progress_t > STUCK_TIMEOUT_S or (
            blocked_s >= BLOCKED_RECOVER_S and peer is None
        ):
            self._recover(now, pose)

    # -- detours: recovering and giving way ---------------------------------------------

    def _recover(self, now: float, pose, why: str = "no progress") -> None:
        target = self.assignment.target if self.assignment is not None else -1
        n = self._recoveries[target] = self._recoveries.get(target, 0) + 1
        if n > MAX_RECOVERIES:
            self.follower.set_path(None)
            self._set(Mode.STUCK, f"{why} after {MAX_RECOVERIES} recoveries")
            return
        back = self._way_back(pose)
        log.info("%s: %s, recovering (%d): back %.1f m", self.id, why, n, len(back) * 0.1)
        self.follower.set_path(back if len(back) else None)
        self._until = now + RECOVER_S
        self._set(Mode.RECOVER, f"{why}: back along the trail ({n})")

    def _give_way(self, rid: str, other: np.ndarray, now: float, pose) -> None:
        goal = self.planning.yield_point(np.asarray(pose[:2]), other)
        if goal is None:
            return
        log.info("%s: giving way to %s", self.id, rid)
        self._blocked_since, self.blocked_by = None, ""
        self.follower.set_path(np.array([pose[:2], goal]))
        self._until = now + YIELD_S
        self._set(Mode.YIELD, f"giving way to {rid}")

    def _detour(self, now: float, pose, scan_xy, moving):
        """Follow the recovery's or the yield's short path; then navigate again."""
        cmd = None
        if self.follower.path is not None:
            cmd = self.follower.command(pose, scan_xy, moving)
        if cmd is None and self.mode == Mode.RECOVER and now < self._until:
            return (0.0, 0.5 * self.max_w)  # no trail to go back on: turn and look around
        if cmd is None or cmd.state == Follow.ARRIVED or now >= self._until:
            self.follower.set_path(None)
            self._progress_t, self._best_remaining = now, math.inf
            self._blocked_since = None
            self._set(Mode.NAVIGATE)
            self._plan(now, pose)
            return (0.0, 0.0)
        return (cmd.v_mps, cmd.w_radps)

    def _record_trail(self, pose) -> None:
        if not self._trail or math.dist(self._trail[-1], pose[:2]) >= TRAIL_STEP_M:
            self._trail.append((float(pose[0]), float(pose[1])))

    def _way_back(self, pose) -> np.ndarray:
        """The trail back to ``RECOVER_BACK_M`` behind the robot, as a path; the points
        taken leave the trail (a second recovery goes on further back)."""
        pts, run = [np.asarray(pose[:2])], 0.0
        while self._trail:
            q = np.asarray(self._trail.pop())
            run += float(np.hypot(*(q - pts[-1])))
            pts.append(q)
            if run >= RECOVER_BACK_M:
                break
        return np.array(pts[1:]) if run >= 0.3 * RECOVER_BACK_M else np.zeros((0, 2))

    def _nearest_peer(self, now: float, pose):
        best = None
        for rid, (t, xy) in self.peers.items():
            d = float(np.hypot(*(xy - pose[:2])))
            if now - t <= PEER_FRESH_S and d <= PEER_NEAR_M and (best is None or d < best[2]):
                best = (rid, xy, d)
        return best

    # -- planning -------------------------------------------------------------------------

    def _plan(self, now: float, pose) -> None:
        a = self.assignment
        if a is None or a.kind == AssignmentKind.STOP:
            return
        self._last_plan = now
        self.plans += 1
        try:
            # a frontier's goal past a cut in the free space (a frontier just beyond a
            # narrow door): drive as close as the map lets and look from there
            path = self.planning.plan(
                np.asarray(pose[:2]), np.array(a.goal), a.kind == AssignmentKind.EXPLORE
            )
        except PlanningError as e:
            self.plan_failures += 1
            self.follower.set_path(None)
            # the map may not hold the way yet (a delta in flight, a resync): retry for a
            # while before telling the coordinator
            if self._fail_since is None:
                self._fail_since = now
            if now - self._fail_since < UNREACHABLE_AFTER_S:
                self._set(Mode.NAVIGATE, f"no path yet ({e}); retrying")
            elif isinstance(e, OffMapError):
                # standing where the map knows nothing, it plans no path to any goal (the
                # coordinator none from it either: office seed 1 stood 900 s): back to
                # where it came from, or turn and look
                self._fail_since = None
                self._recover(now, pose, "off the map")
            else:
                self._set(Mode.UNREACHABLE, str(e))
            return
        self._fail_since = None
        first = self.follower.path is None
        self.follower.set_path(path.points)
        if first or self.mode != Mode.NAVIGATE:
            self._best_remaining, self._progress_t = math.inf, now
        short = "" if path.reaches_goal else ", as close as the map lets"
        self._set(Mode.NAVIGATE, f"{path.length_m:.1f} m to go{short}")

    def _set(self, mode: Mode, detail: str = "") -> None:
        if mode != self.mode or detail != self.detail:
            log.info("%s: %s %s", self.id, mode, detail)
            self.changed = self.changed or WIRE_STATE.get(mode) != WIRE_STATE.get(self.mode)
            self.changed = self.changed or detail != self.detail
            self.mode, self.detail = mode, detail


def priority(robot_id: str) -> tuple:
    """Robots give way in id order (r2 gives way to r1; r10 to r9)."""
    digits = "".join(ch for ch in robot_id if ch.isdigit())
    return (int(digits) if digits else 0, robot_id)
