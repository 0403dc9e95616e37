"""Local control: follow a planned path while avoiding what the live scan sees.

A dynamic-window controller (Fox, Burgard and Thrun 1997) around a pure-pursuit
carrot: candidate (v, w) pairs are rolled out for ``horizon_s`` from the velocity the
base has (it reaches a command at its accelerations); arcs that come closer
than the robot radius plus a margin to any scan point (walls, other robots, anything
the map does not know) are refused; the rest are scored by heading towards the carrot,
speed and clearance. A carrot far to the side turns the robot in place first (a round
robot turning in place sweeps nothing).

    ctl = PathFollower(ControlParams(radius_m=0.2, max_v_mps=0.5, max_w_radps=1.5))
    ctl.set_path(path_xy)
    cmd = ctl.command(pose, scan_xy_robot_frame)   # Command(v, w, state)
    ctl.sent(cmd.v_mps, cmd.w_radps)               # what went to the base this period

Blocked with nothing safe ahead, it backs off if pressed against something, else turns
in place: away from the nearest point in front (for at most a quarter turn) when the
carrot lies ahead or on that side, else towards the carrot.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from polyswarm.se2 import wrap

CREEP_MARGIN_M = 0.01  # blocked at the normal margin: creep past with this much room
CREEP_MPS = 0.1
LOOKAHEAD_STEPS = (1.0, 0.7, 0.45, 0.25)  # fractions of the lookahead tried for the carrot
ESCAPE_MPS = 0.05  # pressed against an obstacle ahead: back off this slowly...
ESCAPE_TRIGGER_M = 0.02  # ... when something is this much inside the safety margin
ESCAPE_CHECK_M = 0.15  # ... and the way back is clear for this far
ESCAPE_TURN_RADPS = 0.5  # blocked with the carrot ahead: turn away from the nearest point...
ESCAPE_TURN_MAX_RAD = math.pi / 2  # ... by at most this much (then it lies beside the robot)
INSIDE_SLACK_M = 0.005  # an arc may pass a point inside the margin this much closer than now


class Follow(StrEnum):
    IDLE = "idle"
    DRIVING = "driving"
    TURNING = "turning"
    BLOCKED = "blocked"  # no admissible motion towards the carrot
    ARRIVED = "arrived"


@dataclass(frozen=True)
class ControlParams:
    radius_m: float = 0.2
    max_v_mps: float = 0.5
    max_w_radps: float = 1.5
    lookahead_m: float = 1.0  # carrot distance along the path (about 2 s at full speed)
    goal_tolerance_m: float = 0.25
    safety_margin_m: float = 0.03  # arcs keep radius + this from every scan point (3 sigma)
    dynamic_margin_m: float = 0.2  # ... and this much more from what the map does not explain
    horizon_s: float = 1.2  # arcs are rolled out this far
    turn_in_place_rad: float = 1.0  # carrot farther off the heading: turn first
    v_samples: int = 6
    w_samples: int = 15
    # the base reaches a commanded velocity at these accelerations (the simulator's): arcs
    # are rolled out from the velocity the robot has, not from the one it is told
    max_accel_mps2: float = 1.0
    max_angular_accel_radps2: float = 3.0
    period_s: float = 0.1  # one command per scan


@dataclass(frozen=True)
class Command:
    v_mps: float
    w_radps: float
    state: Follow


class PathFollower:
    def __init__(self, params: ControlParams) -> None:
        self.p = params
        self.path: np.ndarray | None = None
        self._progress = 0  # index of the path segment the robot is on
        self._escape: tuple[float, float] | None = None  # (heading at its start, turn sign)
        self._velocity = np.zeros(2)  # (v, w) the robot has: see ``sent``
        vs = np.linspace(0.0, params.max_v_mps, params.v_samples)
        ws = np.linspace(-params.max_w_radps, params.max_w_radps, params.w_samples)
        v, w = np.meshgrid(vs, ws, indexing="ij")
        self._v, self._w = v.ravel(), w.ravel()

    def sent(self, v_mps: float, w_radps: float) -> None:
        """The command sent to the base this period (the caller may have replaced ours):
        the velocity the robot will have at the next call, given its accelerations."""
        p = self.p
        dv = np.array([p.max_accel_mps2, p.max_angular_accel_radps2]) * p.period_s
        self._velocity = self._velocity + np.clip(
            np.array([v_mps, w_radps]) - self._velocity, -dv, dv
        )

    def _rollouts(self, velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions (robot frame) of every candidate over the horizon, (n_cand, 6, 2),
        and its heading at the end: the base goes from ``velocity`` to the candidate's
        at its accelerations, then holds it."""
        p = self.p
        n = 12
        dt = p.horizon_s / n
        t = dt * np.arange(1, n + 1)
        v = velocity[0] + np.clip(
            self._v[:, None] - velocity[0], -p.max_accel_mps2 * t, p.max_accel_mps2 * t
        )
        w = velocity[1] + np.clip(
            self._w[:, None] - velocity[1],
            -p.max_angular_accel_radps2 * t,
            p.max_angular_accel_radps2 * t,
        )
        th = np.cumsum(w * dt, axis=1)
        mid = th - 0.5 * w * dt  # heading in the middle of each step
        x = np.cumsum(v * dt * np.cos(mid), axis=1)
        y = np.cumsum(v * dt * np.sin(mid), axis=1)
        arcs = np.stack([x, y], axis=-1)[:, 1::2, :]  # every other step: 6 samples
        return arcs, th[:, -1]

    @property
    def progress(self) -> int:
        """Index of the path segment the robot is on."""
        return self._progress

    def set_path(self, points: np.ndarray | None) -> None:
        self.path = None if points is None or len(points) == 0 else np.asarray(points, float)
        self._progress = 0
        self._escape = None

    @property
    def goal(self) -> np.ndarray | None:
        return None if self.path is None else self.path[-1]

    def remaining_m(self, pose) -> float:
        if self.path is None:
            return 0.0
        p = np.asarray(pose[:2], dtype=float)
        rest = self.path[self._progress + 1 :]
        if len(rest) == 0:
            return float(np.hypot(*(self.path[-1] - p)))
        return float(np.hypot(*(rest[0] - p)) + np.hypot(*np.diff(rest, axis=0).T).sum())

    def command(self, pose, obstacles_xy: np.ndarray, moving: np.ndarray | None = None) -> Command:
        """Velocity for the robot at ``pose`` (map frame) given scan points in the robot
        frame (metres, x forward). ``moving`` flags points the map does not explain
        (other robots, people): they are kept ``dynamic_margin_m`` farther away."""
        if self.path is None:
            return Command(0.0, 0.0, Follow.IDLE)
        pose = np.asarray(pose, dtype=float)
        if np.hypot(*(self.path[-1] - pose[:2])) <= self.p.goal_tolerance_m:
            return Command(0.0, 0.0, Follow.ARRIVED)
        obs = np.asarray(obstacles_xy, dtype=float).reshape(-1, 2)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        # the farthest carrot (up to the lookahead) the robot can drive straight to: a
        # carrot beyond a door jamb would pull the robot into the jamb
        local = None
        for frac in LOOKAHEAD_STEPS:
            carrot = self._carrot(pose[:2], frac * self.p.lookahead_m)
            d = carrot - pose[:2]
            local = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])
            if _segment_clearance(local, obs) >= self.p.radius_m + self.p.safety_margin_m:
                break
        bearing = math.atan2(local[1], local[0])
        if self._escape is None and abs(bearing) > self.p.turn_in_place_rad:
            w = math.copysign(self.p.max_w_radps, bearing) * min(1.0, abs(bearing))
            return Command(0.0, w, Follow.TURNING)
        extra = np.zeros(len(obs)) if moving is None else np.where(moving, 1.0, 0.0)
        return self._window(local, bearing, obs, extra, float(pose[2]))

    def _carrot(self, p: np.ndarray, lookahead_m: float) -> np.ndarray:
        path = self.path
        if len(path) == 1:
            return path[0]
        # advance along the path: the closest segment at or after the current one
        a, b = path[:-1], path[1:]
        ab = b - a
        L2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12)
        t = np.clip(np.einsum("ij,ij->i", p - a, ab) / L2, 0.0, 1.0)
        dist = np.hypot(*(a + t[:, None] * ab - p).T)
        window = slice(self._progress, min(len(a), self._progress + 4))
        k = self._progress + int(np.argmin(dist[window]))
        self._progress = k
        # walk lookahead metres along the path from the projection
        q = a[k] + t[k] * ab[k]
        left = lookahead_m
        pts = np.vstack([q, path[k + 1 :]])
        for u, v in itertools.pairwise(pts):
            seg = float(np.hypot(*(v - u)))
            if seg >= left:
                return u + (v - u) * (left / max(seg, 1e-12))
            left -= seg
        return path[-1]

    def _window(
        self,
        carrot: np.ndarray,
        bearing: float,
        obstacles: np.ndarray,
        moving: np.ndarray,
        heading: float,
    ) -> Command:
        p = self.p
        arcs, end_heading = self._rollouts(self._velocity)
        reach = p.max_v_mps * p.horizon_s + p.radius_m + p.safety_margin_m + p.dynamic_margin_m
        near = np.hypot(obstacles[:, 0], obstacles[:, 1]) < reach + 0.5
        obs, moving = obstacles[near], moving[near]
        if len(obs):
            diff = arcs[:, :, None, :] - obs[None, None, :, :]
            dist = np.sqrt((diff**2).sum(-1)).min(axis=1)  # (candidates, points)
        else:
            dist = np.full((len(self._v), 0), np.inf)
        # progress: how much closer the arc's end is to the carrot, and its heading there
        end = arcs[:, -1, :]
        to_carrot = np.arctan2(carrot[1] - end[:, 1], carrot[0] - end[:, 0])
        err = np.abs(wrap(to_carrot - end_heading))
        gain = np.hypot(*carrot) - np.hypot(*(carrot - end).T)
        forward = self._v > 0
        now = np.hypot(obs[:, 0], obs[:, 1])  # distance of each point from the robot now
        for need, dyn, v_cap in (
            (p.radius_m + p.safety_margin_m, p.dynamic_margin_m, p.max_v_mps),
            # squeeze past slowly
            (p.radius_m + CREEP_MARGIN_M, 0.5 * p.dynamic_margin_m, CREEP_MPS),
        ):
            if dist.shape[1]:
                clear = (dist - dyn * moving[None, :]).min(axis=1)
                # a point already inside the margin (a robot that came close, a wall the
                # map does not explain yet) only forbids arcs that get closer still: the
                # robot may always move away from it, or it would wait there for ever;
                # never closer than the creeping margin (the slack must not add up)
                req = np.minimum(need + dyn * moving, now - INSIDE_SLACK_M)
                req = np.maximum(req, p.radius_m + CREEP_MARGIN_M)
                safe = (dist >= req[None, :]).all(axis=1)
            else:
                clear = np.full(len(self._v), np.inf)
                safe = np.ones(len(self._v), dtype=bool)
            ok = forward & safe & (self._v <= v_cap + 1e-9) & (gain > 0)
            if ok.any():
                score = (
                    2.0 * gain / max(p.max_v_mps * p.horizon_s, 1e-9)
                    - 0.5 * err
                    + 0.5 * np.minimum(clear - need, 0.3)
                )
                k = int(np.argmax(np.where(ok, score, -np.inf)))
                self._escape = None
                return Command(float(self._v[k]), float(self._w[k]), Follow.DRIVING)
        # nothing moving forward is safe. Pressed against something in front: back away
        # from it. Else turn in place (a round robot turning touches nothing): on with an
        # escape turn begun before; away from the nearest point in front when the carrot
        # lies ahead or on that point's side (turning towards the carrot there changes
        # nothing: a robot waited in front of a corner for ever), until a forward arc is
        # safe or a quarter turn is done (no turning back and forth between the carrot
        # and the point); else towards the carrot; else wait for the way to clear
        if self._can_back_off(obstacles):
            self._escape = None
            return Command(-ESCAPE_MPS, 0.0, Follow.BLOCKED)
        if self._escape is None:
            blocker = _nearest_in_front(obstacles, reach)
            if blocker is not None and (abs(bearing) <= 0.15 or bearing * blocker[1] > 0):
                self._escape = (heading, -math.copysign(1.0, blocker[1]))
        if self._escape is not None:
            start, sign = self._escape
            if abs(wrap(heading - start)) < ESCAPE_TURN_MAX_RAD:
                return Command(0.0, sign * ESCAPE_TURN_RADPS, Follow.BLOCKED)
            self._escape = None
            return Command(0.0, 0.0, Follow.BLOCKED)
        if abs(bearing) > 0.15:
            w = math.copysign(min(p.max_w_radps, 2.0 * abs(bearing)), bearing)
            return Command(0.0, w, Follow.BLOCKED)
        return Command(0.0, 0.0, Follow.BLOCKED)

    def _can_back_off(self, obstacles: np.ndarray) -> bool:
        """Something is within the safety margin ahead and the way back is clear."""
        p = self.p
        if not len(obstacles):
            return False
        d = np.hypot(obstacles[:, 0], obstacles[:, 1])
        near_front = (d < p.radius_m + p.safety_margin_m + ESCAPE_TRIGGER_M) & (obstacles[:, 0] > 0)
        if not near_front.any():
            return False
        # the disc swept backwards by ESCAPE_CHECK_M must keep the creep margin
        behind = obstacles[:, 0] < 0
        lateral = np.abs(obstacles[:, 1]) < p.radius_m + CREEP_MARGIN_M
        reach = obstacles[:, 0] > -(p.radius_m + CREEP_MARGIN_M + ESCAPE_CHECK_M)
        return not (behind & lateral & reach).any()


def _nearest_in_front(points: np.ndarray, within_m: float) -> np.ndarray | None:
    """The nearest point ahead of the robot (x > 0, robot frame) closer than ``within_m``,
    off the heading by more than a centimetre (straight ahead, turning either way helps
    no more than backing off)."""
    if not len(points):
        return None
    d = np.hypot(points[:, 0], points[:, 1])
    ok = (points[:, 0] > 0) & (d < within_m)
    if not ok.any():
        return None
    k = int(np.argmin(np.where(ok, d, np.inf)))
    return points[k] if abs(points[k, 1]) > 0.01 else None


def _segment_clearance(end: np.ndarray, points: np.ndarray) -> float:
    """Smallest distance of ``points`` to the segment from the origin to ``end``."""
    if not len(points):
        return math.inf
    L2 = float(end @ end)
    t = np.clip(points @ end / L2, 0.0, 1.0) if L2 > 0 else np.zeros(len(points))
    return float(np.hypot(*(points - t[:, None] * end[None, :]).T).min())
