"""The simulator: pybullet walls, differential-drive robots, 2D lidars, wheel odometry.

Typical use::

    from sim import Simulation, load_world
    with Simulation(load_world("office"), cfg.sim, n_robots=3) as sim:
        sim.set_cmd(0, 0.3, 0.1)
        for event in sim.run(5.0):          # scans as they happen
            event.robot, event.scan, event.odom, event.true_pose

Robots are kinematic: each physics step integrates the commanded velocities (with
acceleration limits) and asks pybullet whether the robot would touch a wall at its
new pose; other robots are cylinders, checked analytically. A move that would touch is
not made, so a robot never passes through a wall; the contact is reported. Lidar scans
are one ``rayTestBatch`` per step for all robots that scan, against the walls as one
static triangle mesh (several times faster than thousands of boxes) and the robots.
Everything random is drawn from generators seeded per robot, so one seed gives
bit-identical scans and odometry.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import mapbox_earcut
import numpy as np
import pybullet
import shapely
from pybullet_utils.bullet_client import BulletClient

from polyswarm.config import SimConfig
from polyswarm.errors import SimulationError
from polyswarm.slam.scan import LaserScan
from sim.lidar import BeamSchedule, BeamsSeen, beam_angles, measure
from sim.shapes import WALL_HEIGHT_M, World, dark_surfaces
from sim.starts import spread_start_poses

log = logging.getLogger(__name__)

# rays per rayTestBatch call: below pybullet's MAX_RAY_INTERSECTION_BATCH_SIZE (16384; a
# batch of exactly that many returns no results, measured), which 23 robots with
# 720-beam lidars scanning in one step exceed
RAY_BATCH = 8192
ROBOT_HEIGHT_M = 0.4  # body height; the lidar rays run at cfg.lidar.height_m
# rays start at the lidar (the robot's centre): robots have no bodies among the walls, so
# nothing of its own is in the way. (Rays that started outside the body went through a
# wall the robot brushed, and returned from beyond it.)
RAY_START_M = 0.0
# Robots have no collision body among the walls: in pybullet's ray test every convex
# body costs about 1 ms per 720-beam scan, even with collision filters (measured). The
# lidar sees robots as circles, added analytically (exact for cylinders); wall contacts
# are asked of one probe cylinder that is parked far below the floor between queries.
PARKING = (0.0, 0.0, -1000.0)
CONTACT_MARGIN_M = 0.002  # a robot closer than this to a wall or robot is touching it
CONTACT_CLEAR_M = 0.05  # a contact is over once the robot is this far away again


@dataclass
class Robot:
    index: int
    name: str
    pose: np.ndarray  # true (x, y, theta) in the world frame: for evaluation only
    odom: np.ndarray = field(default_factory=lambda: np.zeros(3))  # odometry frame
    v: float = 0.0
    w: float = 0.0
    cmd: tuple[float, float] = (0.0, 0.0)
    distance_m: float = 0.0
    wall_collisions: int = 0
    robot_collisions: int = 0
    blocked: bool = False
    body: int = -1


@dataclass(frozen=True)
class ScanEvent:
    robot: int
    scan: LaserScan
    odom: np.ndarray  # odometry pose when the scan is published (its sweep's end)
    true_pose: np.ndarray  # ground truth then (evaluation only)


@dataclass(frozen=True)
class CollisionEvent:
    robot: int
    time: float
    with_robot: int | None  # None: a wall


def wall_mesh(walls: shapely.Geometry, height: float) -> tuple[np.ndarray, np.ndarray]:
    """Walls extruded to ``height``: side quads for every boundary edge, plus the top."""
    verts, idx = [], []
    n = 0
    for poly in shapely.get_parts(walls):
        rings = [np.asarray(poly.exterior.coords)[:-1]] + [
            np.asarray(r.coords)[:-1] for r in poly.interiors
        ]
        for ring in rings:
            m = len(ring)
            bottom = np.column_stack([ring, np.zeros(m)])
            top = np.column_stack([ring, np.full(m, height)])
            verts += [bottom, top]
            k = np.arange(m)
            nk = (k + 1) % m
            a, b, c, d = n + k, n + nk, n + m + nk, n + m + k
            idx.append(np.stack([a, b, c, a, c, d], axis=1).ravel())
            n += 2 * m
        # top face, so bodies resting on a wall would not fall in
        flat = np.concatenate(rings)
        ends = np.cumsum([len(r) for r in rings]).astype(np.uint32)
        tri = mapbox_earcut.triangulate_float64(flat, ends).astype(np.int64)
        verts.append(np.column_stack([flat, np.full(len(flat), height)]))
        idx.append(tri + n)
        n += len(flat)
    return np.concatenate(verts), np.concatenate(idx)


class Simulation:
    def __init__(
        self,
        world: World,
        config: SimConfig,
        n_robots: int = 1,
        start_poses: Sequence[tuple[float, float, float]] | None = None,
        gui: bool = False,
        walls_as_boxes: bool = False,
    ) -> None:
        if n_robots < 1:
            raise SimulationError("need at least one robot")
        self.world = world
        self.cfg = config
        self.dt = 1.0 / config.physics_hz
        self.scan_every = max(1, round(config.physics_hz / config.lidar.rate_hz))
        self.steps = 0
        self.collisions: list[CollisionEvent] = []
        with _quiet_stdout():  # pybullet prints "argv[0]=" from C on connect
            self._client = BulletClient(connection_mode=pybullet.GUI if gui else pybullet.DIRECT)
        self._client.setGravity(0, 0, 0)
        self.walls_body = self._add_walls(walls_as_boxes)
        poses = (
            list(start_poses)
            if start_poses is not None
            else spread_start_poses(world, n_robots, config.robot.radius_m)
        )
        if len(poses) != n_robots:
            raise SimulationError(f"got {len(poses)} start poses for {n_robots} robots")
        self.robots: list[Robot] = []
        shape = self._client.createCollisionShape(
            pybullet.GEOM_CYLINDER, radius=config.robot.radius_m, height=ROBOT_HEIGHT_M
        )
        self._probe = self._client.createMultiBody(0, shape, -1, PARKING)
        self._gui = gui
        visual = -1
        if gui:
            visual = self._client.createVisualShape(
                pybullet.GEOM_CYLINDER,
                radius=config.robot.radius_m,
                length=ROBOT_HEIGHT_M,
                rgbaColor=[0.1, 0.3, 0.9, 1],
            )
        for k, start in enumerate(poses):
            pose = np.array(start, dtype=float)
            body = -1
            if gui:  # visual only: no collision shape, invisible to ray tests
                body = self._client.createMultiBody(
                    0, -1, visual, [pose[0], pose[1], ROBOT_HEIGHT_M / 2]
                )
            r = Robot(k, f"r{k + 1}", pose, body=body)
            self.robots.append(r)
            if self._touches_wall(pose) or self._touching_robot(k, pose) is not None:
                raise SimulationError(f"start pose {tuple(pose)} of robot {r.name} is not free")
        self._lidar_rng = [np.random.default_rng([config.seed, k, 0]) for k in range(n_robots)]
        self._odom_rng = [np.random.default_rng([config.seed, k, 1]) for k in range(n_robots)]
        # systematic odometry errors of each robot: its wheels' radius and base, drawn once
        noise = config.odometry_noise
        self._odom_scale = [
            (
                1.0
                + noise.scale_sigma * float(np.random.default_rng([config.seed, k, 2]).normal()),
                1.0
                + noise.turn_scale_sigma
                * float(np.random.default_rng([config.seed, k, 3]).normal()),
            )
            for k in range(n_robots)
        ]
        self.angles = beam_angles(config.lidar)
        self._cos, self._sin = np.cos(self.angles), np.sin(self.angles)
        self._sweep = BeamSchedule.make(config.lidar, self.angles, self.scan_every, self.dt)
        self._ranges = np.full((n_robots, len(self.angles)), np.inf)  # the sweep so far
        self._incidence = np.full((n_robots, len(self.angles)), np.nan)  # ... its incidences
        self._on_dark = np.zeros((n_robots, len(self.angles)), dtype=bool)  # ... dark surfaces
        self._dark = dark_surfaces(world, config.dark_surface_share, config.seed)
        shapely.prepare(self._dark)
        self._prev = [r.pose.copy() for r in self.robots]  # poses before the current step

    # -- setup --------------------------------------------------------------------------

    def _add_walls(self, as_boxes: bool) -> int:
        c = self._client
        if as_boxes:
            boxes = self.world.boxes
            if boxes is None:
                boxes = np.array([g.bounds for g in shapely.get_parts(self.world.walls)])
            shapes, positions = [], []
            for x0, y0, x1, y1 in boxes:
                shapes.append([(x1 - x0) / 2, (y1 - y0) / 2, WALL_HEIGHT_M / 2])
                positions.append([(x0 + x1) / 2, (y0 + y1) / 2, WALL_HEIGHT_M / 2])
            body = -1
            # pybullet limits links per body; one static body per box is simplest
            for half, pos in zip(shapes, positions, strict=True):
                s = c.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
                body = c.createMultiBody(0, s, -1, pos)
            return body
        verts, idx = wall_mesh(self.world.walls, WALL_HEIGHT_M)
        shape = c.createCollisionShape(
            pybullet.GEOM_MESH,
            vertices=verts.tolist(),
            indices=idx.astype(np.int32).tolist(),
            flags=pybullet.GEOM_FORCE_CONCAVE_TRIMESH,
        )
        visual = c.createVisualShape(
            pybullet.GEOM_MESH,
            vertices=verts.tolist(),
            indices=idx.astype(np.int32).tolist(),
            rgbaColor=[0.6, 0.6, 0.6, 1],
        )
        return c.createMultiBody(0, shape, visual, [0, 0, 0])

    def close(self) -> None:
        if self._client is not None:
            self._client.disconnect()
            self._client = None

    def __enter__(self) -> Simulation:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- state --------------------------------------------------------------------------

    @property
    def time(self) -> float:
        return self.steps * self.dt

    def set_cmd(self, robot: int, v: float, w: float) -> None:
        """Velocity command (m/s, rad/s); clipped to the robot's limits."""
        if not (math.isfinite(v) and math.isfinite(w)):
            raise SimulationError(f"velocity command must be finite, got ({v}, {w})")
        rc = self.cfg.robot
        self.robots[robot].cmd = (
            float(np.clip(v, -rc.max_linear_mps, rc.max_linear_mps)),
            float(np.clip(w, -rc.max_angular_radps, rc.max_angular_radps)),
        )

    def _show(self, r: Robot) -> None:
        if r.body >= 0:
            q = self._client.getQuaternionFromEuler([0, 0, float(r.pose[2])])
            self._client.resetBasePositionAndOrientation(
                r.body, [r.pose[0], r.pose[1], ROBOT_HEIGHT_M / 2], q
            )

    def _touches_wall(self, pose: np.ndarray, margin: float = CONTACT_MARGIN_M) -> bool:
        c = self._client
        c.resetBasePositionAndOrientation(
            self._probe, [pose[0], pose[1], ROBOT_HEIGHT_M / 2], [0, 0, 0, 1]
        )
        hit = len(c.getClosestPoints(self._probe, self.walls_body, margin)) > 0
        c.resetBasePositionAndOrientation(self._probe, PARKING, [0, 0, 0, 1])
        return hit

    def _touching_robot(
        self, k: int, pose: np.ndarray, margin: float = CONTACT_MARGIN_M
    ) -> int | None:
        lim = 2 * self.cfg.robot.radius_m + margin
        for o in self.robots:
            if o.index != k and math.hypot(o.pose[0] - pose[0], o.pose[1] - pose[1]) < lim:
                return o.index
        return None

    def state(self) -> dict:
        """What a restarted simulator needs to go on where this one is (JSON-able): the
        time, each robot's true pose, odometry, speeds and counts, the noise generators."""
        return {
            "steps": self.steps,
            "robots": [
                {
                    "pose": r.pose.tolist(),
                    "odom": r.odom.tolist(),
                    "v": r.v,
                    "w": r.w,
                    "distance_m": r.distance_m,
                    "wall_collisions": r.wall_collisions,
                    "robot_collisions": r.robot_collisions,
                    "blocked": r.blocked,
                }
                for r in self.robots
            ],
            "lidar_rng": [g.bit_generator.state for g in self._lidar_rng],
            "odom_rng": [g.bit_generator.state for g in self._odom_rng],
        }

    def restore(self, state: dict, steps_ahead: int = 0) -> None:
        """Go on from ``state`` (``state()`` of a simulator of the same world, config and
        robots), ``steps_ahead`` physics steps later (rounded up to a whole scan), so
        that nothing is stamped earlier than what the old simulator already sent.
        Robots keep their poses and odometry. Raises SimulationError on a mismatch."""
        robots = state.get("robots", [])
        if len(robots) != len(self.robots):
            raise SimulationError(f"state of {len(robots)} robots, simulating {len(self.robots)}")
        for r, saved in zip(self.robots, robots, strict=True):
            r.pose = np.array(saved["pose"], dtype=float)
            r.odom = np.array(saved["odom"], dtype=float)
            r.v, r.w = float(saved["v"]), float(saved["w"])
            r.distance_m = float(saved["distance_m"])
            r.wall_collisions = int(saved["wall_collisions"])
            r.robot_collisions = int(saved["robot_collisions"])
            r.blocked = bool(saved["blocked"])
            self._show(r)
        for g, st in zip(
            self._lidar_rng + self._odom_rng, state["lidar_rng"] + state["odom_rng"], strict=True
        ):
            g.bit_generator.state = st
        steps = int(state["steps"]) + max(0, steps_ahead)
        self.steps = -(-steps // self.scan_every) * self.scan_every  # a sweep starts anew
        self._ranges[:] = np.inf
        self._incidence[:] = np.nan
        self._on_dark[:] = False
        self._prev = [r.pose.copy() for r in self.robots]

    # -- stepping -----------------------------------------------------------------------

    def step(self) -> list[ScanEvent]:
        """Advance one physics step; returns the scans whose sweep ended at the new time."""
        for k, r in enumerate(self.robots):
            self._prev[k] = r.pose.copy()
            self._move(r)
        in_sweep = self.steps % self.scan_every
        self.steps += 1
        beams = np.nonzero(self._sweep.step == in_sweep)[0]
        if len(beams):  # the beams taken during this step, from where the robots were then
            frac = self._sweep.frac[beams]
            for k, seen in enumerate(self._cast(range(len(self.robots)), beams, frac)):
                self._ranges[k, beams] = seen.ranges
                self._incidence[k, beams] = seen.incidence
                self._on_dark[k, beams] = seen.dark
        if self.steps % self.scan_every == 0:
            start = self.time - self._sweep.scan_time_s if self._sweep.time_increment_s else None
            return [
                self._finish(
                    k, BeamsSeen(self._ranges[k], self._incidence[k], self._on_dark[k]), start
                )
                for k in range(len(self.robots))
            ]
        return []

    def run(self, seconds: float) -> Iterator[ScanEvent]:
        for _ in range(round(seconds / self.dt)):
            yield from self.step()

    def _move(self, r: Robot) -> None:
        rc, dt = self.cfg.robot, self.dt
        v_cmd, w_cmd = r.cmd
        r.v += float(
            np.clip(v_cmd - r.v, -rc.max_linear_accel_mps2 * dt, rc.max_linear_accel_mps2 * dt)
        )
        r.w += float(
            np.clip(
                w_cmd - r.w, -rc.max_angular_accel_radps2 * dt, rc.max_angular_accel_radps2 * dt
            )
        )
        if r.v == 0.0 and r.w == 0.0:
            return
        x, y, th = r.pose
        ds, dth = r.v * dt, r.w * dt
        for cand_ds, cand_dth in ((ds, dth), (0.0, dth)):
            if cand_ds == 0.0 and cand_dth == 0.0:
                continue
            new = _integrate(x, y, th, cand_ds, cand_dth)
            # turning on the spot cannot touch anything: the body is a cylinder
            other = self._touching_robot(r.index, new) if cand_ds != 0.0 else None
            wall = self._touches_wall(new) if cand_ds != 0.0 and other is None else False
            if other is None and not wall:
                r.pose = new
                self._show(r)
                r.distance_m += abs(cand_ds)
                self._odometry(r, cand_ds, cand_dth)
                if cand_ds == ds:
                    # a contact ends once the robot is clear by a margin (hysteresis)
                    if r.blocked and not self._touches_wall(new, CONTACT_CLEAR_M):
                        r.blocked = self._touching_robot(r.index, new, CONTACT_CLEAR_M) is not None
                    return
                break
            if not r.blocked:  # report a contact once, when it starts
                self.collisions.append(CollisionEvent(r.index, self.time, other))
                log.info(
                    "%s touched %s at %.1f s (x %.2f m, y %.2f m, heading %.2f rad, v %.2f m/s)",
                    r.name,
                    "a wall" if other is None else f"robot {other}",
                    self.time,
                    x,
                    y,
                    th,
                    r.v,
                )
                if other is None:
                    r.wall_collisions += 1
                else:
                    r.robot_collisions += 1
            r.blocked = True
        r.v = 0.0  # the translation was refused: the robot stops

    def _odometry(self, r: Robot, ds: float, dth: float) -> None:
        n = self.cfg.odometry_noise
        rng = self._odom_rng[r.index]
        e = rng.standard_normal(3)
        d = abs(ds)
        scale, turn_scale = self._odom_scale[r.index]
        ds_n = scale * ds + e[0] * n.trans_sigma_per_sqrt_m * math.sqrt(d)
        lat = e[1] * n.lateral_sigma_per_sqrt_m * math.sqrt(d)
        dth_n = turn_scale * dth + e[2] * math.sqrt(
            n.rot_sigma_per_sqrt_rad**2 * abs(dth) + n.rot_sigma_per_sqrt_m**2 * d
        )
        x, y, th = r.odom
        new = _integrate(x, y, th, ds_n, dth_n)  # the same arc model as the true motion
        mid = th + dth_n / 2
        new[0] -= lat * math.sin(mid)
        new[1] += lat * math.cos(mid)
        r.odom = new

    def _robot_hits(self, x, y, dx, dy, k: int) -> np.ndarray:
        """Ranges along rays (x, y) + t (dx, dy) of robot k's sensor to the other robots'
        bodies (inf: none)."""
        out = np.full(len(dx), np.inf)
        reach = self.cfg.lidar.range_max_m + self.cfg.robot.radius_m
        for o in self.robots:
            if o.index != k and np.hypot(o.pose[0] - x, o.pose[1] - y).min() < reach:
                out = np.minimum(
                    out, _ray_circle(x, y, dx, dy, o.pose[0], o.pose[1], self.cfg.robot.radius_m)
                )
        out[out > self.cfg.lidar.range_max_m] = np.inf
        return out

    def scan(self, which=None) -> list[ScanEvent]:
        """Scan now with the given robots (all by default), every beam at once, without
        stepping."""
        which = list(range(len(self.robots)) if which is None else which)
        every = np.arange(len(self.angles))
        cast = self._cast(which, every, np.ones(len(every)))
        return [self._finish(k, seen, None) for k, seen in zip(which, cast, strict=True)]

    def _cast(self, which, beams: np.ndarray, frac: np.ndarray) -> list[BeamsSeen]:
        """What the given beams of each robot in ``which`` meet (true ranges, inf: nothing
        within range; incidences; dark surfaces), each beam from the robot's pose at
        ``frac`` of the last step."""
        lid = self.cfg.lidar
        r0 = RAY_START_M
        frm, to, rays = [], [], []
        for k in which:
            a, b = self._prev[k], self.robots[k].pose
            x = a[0] + frac * (b[0] - a[0])
            y = a[1] + frac * (b[1] - a[1])
            th = a[2] + frac * math.remainder(b[2] - a[2], 2 * math.pi)
            c, s = np.cos(th), np.sin(th)
            dx = c * self._cos[beams] - s * self._sin[beams]
            dy = s * self._cos[beams] + c * self._sin[beams]
            z = np.full(len(dx), lid.height_m)
            frm.append(np.column_stack([x + r0 * dx, y + r0 * dy, z]))
            to.append(np.column_stack([x + lid.range_max_m * dx, y + lid.range_max_m * dy, z]))
            rays.append((x, y, dx, dy))
        frm, to = np.vstack(frm), np.vstack(to)
        res = []  # pybullet casts fewer than MAX_RAY_INTERSECTION_BATCH_SIZE rays per call
        for k in range(0, len(frm), RAY_BATCH):
            res += self._client.rayTestBatch(
                frm[k : k + RAY_BATCH], to[k : k + RAY_BATCH], numThreads=self.cfg.raycast_threads
            )
        if len(res) != len(frm):  # pragma: no cover - a pybullet that casts fewer
            raise SimulationError(f"pybullet cast {len(res)} of {len(frm)} rays")
        frac_hit = np.fromiter((h[2] for h in res), dtype=float, count=len(res))
        hit = np.fromiter((h[0] >= 0 for h in res), dtype=bool, count=len(res))
        normal = np.array([h[4][:2] for h in res], dtype=float).reshape(-1, 2)
        out, n = [], len(beams)
        for i, k in enumerate(which):
            part = slice(i * n, (i + 1) * n)
            f, h = frac_hit[part], hit[part]
            walls = np.where(h, r0 + f * (lid.range_max_m - r0), np.inf)
            x, y, dx, dy = rays[i]
            cos = np.abs(normal[part, 0] * dx + normal[part, 1] * dy)
            incidence = np.where(h, np.arccos(np.clip(cos, 0.0, 1.0)), np.nan)
            t = np.where(h, walls, 0.0)
            dark = h & shapely.intersects_xy(self._dark, x + t * dx, y + t * dy)
            robots = self._robot_hits(x, y, dx, dy, k)
            nearer = robots < walls  # another robot: met head-on, not dark
            ranges = np.minimum(walls, robots)
            out.append(
                BeamsSeen(ranges, np.where(nearer, 0.0, incidence), np.where(nearer, False, dark))
            )
        return out

    def _finish(self, k: int, seen: BeamsSeen, start: float | None) -> ScanEvent:
        """The scan robot k's driver publishes; ``start``: its first beam's time (a
        rolling sweep), None: every beam now."""
        lid = self.cfg.lidar
        ranges = measure(seen, lid, self._lidar_rng[k])
        rolling = start is not None
        scan = LaserScan(
            ranges,
            float(self.angles[0]),
            float(self.angles[1] - self.angles[0]),
            lid.range_min_m,
            lid.range_max_m,
            start if rolling else self.time,
            self._sweep.time_increment_s if rolling else 0.0,
            self._sweep.scan_time_s,
        )
        rob = self.robots[k]
        return ScanEvent(k, scan, rob.odom.copy(), rob.pose.copy())


@contextlib.contextmanager
def _quiet_stdout():
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # no real stdout (e.g. captured)
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), fd)
            yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)


def _ray_circle(ox, oy, dx, dy, cx, cy, radius) -> np.ndarray:
    """Distance along unit rays (o, d) to a circle; inf where a ray misses it."""
    px, py = cx - ox, cy - oy
    b = dx * px + dy * py
    disc = b * b - (px * px + py * py - radius * radius)
    with np.errstate(invalid="ignore"):
        t = b - np.sqrt(disc)
    return np.where((disc >= 0) & (t > 0), t, np.inf)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _integrate(x: float, y: float, th: float, ds: float, dth: float) -> np.ndarray:
    """Exact unicycle motion over one step (arc of length ds turning by dth)."""
    if abs(dth) < 1e-9:
        return np.array([x + ds * math.cos(th), y + ds * math.sin(th), th])
    rad = ds / dth
    return np.array(
        [
            x + rad * (math.sin(th + dth) - math.sin(th)),
            y - rad * (math.cos(th + dth) - math.cos(th)),
            _wrap(th + dth),
        ]
    )
