"""The robot agent: PolySLAM, navigation and local control for one robot.

``RobotAgent`` is the robot's brain and knows nothing of Zenoh: it takes scans,
odometry, assignments and merged-map updates, and returns what to send. ``run_agent``
wires it to a Zenoh session. The same program runs on a real robot; only the source
of scans and odometry and the sink of velocity commands change.

Per scan (``RobotAgent.on_scan``), in order:
  1. odometry at the scan time, and over its sweep (de-skewing);
  2. PolySLAM (pre-align, ICP, keyframe polygon, refine, merge): pose and map delta;
  3. behaviour (``agents.behaviour``): plan to the assigned goal on the merged map (own
     map without one), follow the path around what the scan sees, look, recover, give
     way: the velocity command;
  4. what to send: pose, the map delta, the state for the coordinator.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from agents.alone import Alone
from agents.behaviour import Behaviour
from agents.peers import Peers
from agents.seen import SeenObstacles
from polyswarm.config import CommandOutput, Config, SensorSource, known_starts
from polyswarm.errors import (
    DeltaGapError,
    PlanningError,
)
from polyswarm.explore.targets import Sensor
from polyswarm.frames.sighting import PROFILE_PERIOD_S, clear_profile
from polyswarm.nav.control import ControlParams, PathFollower
from polyswarm.nav.guard import guard
from polyswarm.nav.navgraph import NavGraph, clear_of
from polyswarm.nav.planner import Planner
from polyswarm.nav.recent import RecentReturns
from polyswarm.polymap import GridPolyMap, MapDelta, MergeOp, VectorType
from polyswarm.se2 import compose, transform_points
from polyswarm.slam.follow import CorrectionOp, pose_of
from polyswarm.slam.odometry import OdometryBuffer
from polyswarm.slam.polyslam import PolySlam
from polyswarm.slam.scan import LaserScan, beam_angles, classify, deskew_motion, scan_to_points
from protocols.keys import check_name
from protocols.messages import (
    MAX_STATUS_PATH_POINTS,
    Anchor,
    Assignment,
    AssignmentKind,
    Odometry,
    Pose,
    Priors,
    RobotState,
    RobotStatus,
    Scan,
)

log = logging.getLogger(__name__)

POSE_PERIOD_S = 0.5  # pose messages to the coordinator (2 Hz)
STATUS_PERIOD_S = 1.0
UNEXPLAINED_M = 0.15  # a scan point this far from the map's obstacles is not a wall
NEAR_M = 4.0  # map vectors within this of the robot are used by the local checks
MOUNT_WAIT_SCANS = 20  # scans from a ROS robot without a mount in tf or config: say so
ODOM_BUFFER = 200  # odometry messages kept to find the one at a scan's time
NEAR_OBSTACLE_M = 0.5  # range at which the local controller's margin is judged
MIN_SAFETY_MARGIN_M = 0.03  # the thesis sensor's 3 sigma of 1 cm: never less


@dataclass
class Outbox:
    """What one call of the agent wants sent."""

    cmd: tuple[float, float] | None = None
    pose: Pose | None = None
    delta: MapDelta | None = None
    op: MergeOp | None = None  # the delta as the merge that made it (often smaller)
    correction: CorrectionOp | None = None  # keyframes a loop closure moved, before ``op``
    status: RobotStatus | None = None
    assignment: Assignment | None = None  # one the robot gave itself (``agents.alone``)


@dataclass
class AgentStats:
    scans: int = 0
    keyframes: int = 0
    distance_m: float = 0.0
    peer_returns_masked: int = 0  # scan returns taken for other robots, kept from SLAM
    refused: int = 0  # messages refused: undecodable, or a scan the agent could not use
    slam_ms: list[float] = field(default_factory=list)  # each keyframe's
    slam_s: float = 0.0  # wall seconds spent in PolySLAM on every scan


def safety_margin(lidar) -> float:
    """How far beyond its radius the robot keeps from what its lidar sees: three sigma
    of the range noise at ``NEAR_OBSTACLE_M`` (noisy returns of a wall it passes must
    not stop it), at least the thesis sensor's 3 cm."""
    sigma = lidar.noise_sigma_m + lidar.noise_sigma_per_m * NEAR_OBSTACLE_M
    return max(MIN_SAFETY_MARGIN_M, 3.0 * sigma)


class RobotAgent(Peers):
    def __init__(
        self, robot_id: str, cfg: Config, start_pose=(0.0, 0.0, 0.0), frame_known: bool = True
    ) -> None:
        """``frame_known`` False: nobody gave the robot's start pose; it maps in a frame of
        its own (its start, ``start_pose`` is then (0, 0, 0)) until an ``anchor`` puts
        it into the shared frame (``agents.anchoring``)."""
        self.id = check_name(robot_id, "robot id")
        self.cfg = cfg
        self.start_pose = np.array(start_pose, dtype=float)
        self.frame_known = frame_known
        self.frame = 0  # the last anchor applied
        # that anchor withdrew the frame before it (``Anchor.own``): a frame of its own again
        self.own_frame = False
        self._anchor: Anchor | None = None  # the anchor SLAM applies at the next scan
        # robots whose starts nobody gave: their poses mean nothing here until anchored
        self._own_frames = {rid for rid, st in known_starts(cfg.robots).items() if st is None}
        # send clear profiles (None: when a robot of the swarm started in a frame of its
        # own; benchmarks that know every start but measure the matching set it True)
        self.sightings: bool | None = None
        lidar = cfg.sim.lidar
        self.slam = PolySlam(
            cfg.slam, cfg.map.cell_size_m, self.start_pose, out_of_range=lidar.out_of_range
        )
        self.radius = cfg.nav.obstacle_clearance_m
        rc = cfg.sim.robot
        follower = PathFollower(
            ControlParams(
                radius_m=cfg.nav.robot_radius_m,
                safety_margin_m=safety_margin(lidar),
                max_v_mps=rc.max_linear_mps,
                max_w_radps=rc.max_angular_radps,
                max_accel_mps2=rc.max_linear_accel_mps2,
                max_angular_accel_radps2=rc.max_angular_accel_radps2,
                period_s=1.0 / lidar.rate_hz,
            )
        )
        self.behaviour = Behaviour(self.id, follower, self, rc.max_angular_radps, lidar.fov_rad)
        self.merged: GridPolyMap | None = None
        self._mount_said = False  # the lidar mount's source was logged
        self.seen = SeenObstacles()  # obstacles the lidar sees and the planning map lacks
        self.recent = RecentReturns()  # the last seconds' close returns, for the controller
        self.alone = Alone()  # out of every coordinator's reach: targets of its own
        self._now_s = 0.0
        self.merged_graph: NavGraph | None = None
        self.own_graph: NavGraph | None = None
        self._own_graph_version = -1
        self.pose = self.start_pose.copy()
        self.odometry = OdometryBuffer(ODOM_BUFFER)
        self._last_pose_t = -math.inf
        self._last_status_t = -math.inf
        self._last_clear_t = -math.inf  # the last pose sent with a clear profile
        self._last_odom_xy: np.ndarray | None = None
        self.peers: dict[str, tuple[float, np.ndarray]] = {}  # other robots: (stamp, xy)
        self.stats = AgentStats()
        self.bytes_sent = 0  # maintained by the transport
        self.journaled = 0  # deltas persisted since the last snapshot (0: none yet)

    @property
    def state(self) -> RobotState:
        return self.behaviour.state

    @property
    def assignment(self) -> Assignment | None:
        return self.behaviour.assignment

    @property
    def follower(self) -> PathFollower:
        return self.behaviour.follower

    # -- inputs -----------------------------------------------------------------------------

    def on_odom(self, stamp_s: float, odom: Odometry) -> None:
        pose = np.array([odom.x, odom.y, odom.theta])
        last = self.odometry.latest_s
        if not self.odometry.add(stamp_s, pose):
            log.warning("%s: odometry went back in time (%.3f < %.3f)", self.id, stamp_s, last)
        if self._last_odom_xy is not None:
            self.stats.distance_m += float(np.hypot(*(pose[:2] - self._last_odom_xy)))
        self._last_odom_xy = pose[:2]

    def resume(
        self, pmap: GridPolyMap, pose, odom=None, frame: int = 0, scale=None, own_frame=False
    ) -> None:
        """Continue from a persisted map and pose (the agent was restarted); ``odom``, the
        odometry reading at that pose, lets SLAM follow the robot's motion since;
        ``frame``, the last anchor applied (the map is in the shared frame since, unless
        ``own_frame``: that anchor withdrew it); ``scale``, the odometry's distance scale
        SLAM had learnt."""
        self.slam.resume(pmap, pose, odom, scale)
        self.pose = np.array(pose, dtype=float)
        if frame >= self.frame:
            self.frame, self.own_frame = frame, own_frame

    @property
    def latest_odom_s(self) -> float:
        return self.odometry.latest_s

    def odom_at(self, stamp_s: float) -> np.ndarray | None:
        """Odometry at ``stamp_s``: interpolated between the two around it."""
        return self.odometry.at(stamp_s)

    def on_assignment(self, a: Assignment, now_s: float) -> None:
        self.behaviour.on_assignment(a, now_s, self.pose)

    @property
    def planning_map(self) -> GridPolyMap:
        """The map the robot plans on: the merged map once the coordinator shares one
        (its own while it is alone)."""
        return self._planning_map()[0]

    @property
    def target_xy(self) -> tuple[float, float] | None:
        """Where the robot is sent (an exploration or return goal), or None."""
        a = self.assignment
        return None if a is None or a.target < 0 else a.goal

    @property
    def in_shared_frame(self) -> bool:
        return (self.frame_known or self.frame > 0) and not self.own_frame

    def on_anchor(self, a: Anchor) -> None:
        """The coordinator found where this robot's frame lies in the shared one: SLAM
        moves there at the next scan (an anchor already applied is ignored). An ``own``
        anchor withdraws the frame anchored so far: nothing moves, the robot's
        coordinates are a frame of its own again."""
        if a.frame <= max(self.frame, self._anchor.frame if self._anchor else 0):
            return
        if a.own:
            self._withdrawn(a)
            return
        into = "a team's frame" if a.team else "the shared frame"
        log.info("%s: anchor %d: moving into %s", self.id, a.frame, into)
        self._anchor = a
        self.slam.anchor((a.x, a.y, a.theta))

    def on_priors(self, p: Priors) -> int:
        """Where the swarm's joint pose graph puts some of this robot's keyframes
        (``polyswarm.frames.jointgraph``): held in SLAM's pose graph from the next keyframe
        on. Ignored when they are in another frame than the robot's (an anchor since, or
        its frame withdrawn). The priors taken."""
        if p.frame != self.frame or self.own_frame or self._anchor is not None:
            log.info("%s: priors in frame %d ignored (frame %d)", self.id, p.frame, self.frame)
            return 0
        frames = {kid: np.array(pose_of((x, y, th))) for kid, x, y, th in p.poses}
        n = self.slam.constrain(frames, p.sigma_m, p.sigma_rad)
        log.info("%s: %d of %d keyframe priors from the joint pose graph", self.id, n, len(frames))
        return n

    def _anchored(self, now_s: float) -> None:
        """SLAM moved into the anchor's frame in this step: so do the start, goals, peers.
        A team's frame (``Anchor.team``) is not the shared one: the robot's coordinates
        stay a frame of its own, as far as the swarm is concerned."""
        a, self._anchor = self._anchor, None
        frame = np.array([a.x, a.y, a.theta])
        self.frame, self.own_frame = a.frame, a.team
        self.start_pose = compose(frame, self.start_pose)
        self.behaviour.on_assignment(Assignment(AssignmentKind.STOP, -1), now_s, self.pose)
        self.behaviour.move_frame(frame)
        self.seen = SeenObstacles()  # seen in the old frame: the next scans see them again
        self.peers.clear()
        self.merged = self.merged_graph = None  # the merged map is fetched afresh
        where = "a team's frame" if a.team else "the shared frame"
        log.info("%s: in %s (anchor %d), at %s", self.id, where, a.frame, self.pose)

    def _withdrawn(self, a: Anchor) -> None:
        """The frame anchored so far was found wrong: map, pose and start stay where they
        are, in what is a frame of its own again; goals, the merged map and peers'
        poses (all in the shared frame) are dropped."""
        log.warning("%s: anchor %d: the shared frame is withdrawn", self.id, a.frame)
        self.frame, self.own_frame = a.frame, True
        self.slam.clear_priors()  # the swarm's joint pose graph placed it in that frame
        self.behaviour.on_assignment(Assignment(AssignmentKind.STOP, -1), self._now_s, self.pose)
        self.peers.clear()
        self.merged = self.merged_graph = None

    def on_merged_map(self, pmap: GridPolyMap) -> None:
        """A full merged map (first contact or resync)."""
        if not self.in_shared_frame:
            return  # not in this robot's frame
        self.merged = pmap
        self.merged_graph = NavGraph.for_robot(pmap, self.cfg.nav)

    def on_merged_delta(self, delta: MapDelta) -> None:
        """Raises DeltaGapError when a delta was missed (fetch the full map)."""
        if not self.in_shared_frame:
            return
        if self.merged is None:
            raise DeltaGapError("no merged map yet")
        self.merged = self.merged.apply_delta(delta)
        self.merged_graph.update(self.merged, {c.index for c in delta.cells})

    # -- the per-scan step ------------------------------------------------------------------

    def on_scan(self, stamp_s: float, scan: LaserScan) -> Outbox:
        """One scan; ``stamp_s`` is now (for a rolling sweep: when its last beam was taken,
        the time its points are de-skewed to)."""
        out = Outbox()
        self.stats.scans += 1
        stamp_s = max(stamp_s, scan.end_stamp)
        # 1. odometry at the scan time (its last beam's), and over the sweep for de-skewing
        odom = self.odom_at(scan.end_stamp)
        if odom is None:
            return out
        motion = deskew_motion(scan, self.odometry.at_many)
        # 2. PolySLAM: pose, and on keyframes the map delta (other robots are not walls)
        masked = self._without_peers(scan, stamp_s)
        t0 = time.perf_counter()
        step = self.slam.process(masked, odom, motion, self._blobs_m(stamp_s))
        self.stats.slam_s += time.perf_counter() - t0
        turned = abs(math.remainder(step.pose[2] - self.pose[2], 2 * math.pi))
        if step.anchored:
            turned = 0.0  # the frame moved, not the robot
        self.pose = step.pose
        if step.anchored and self._anchor is not None:
            self._anchored(stamp_s)
        if step.keyframe:
            self.stats.keyframes += 1
            self.stats.slam_ms.append(step.timings_ms.get("total", 0.0))
        out.delta, out.op, out.correction = step.delta, step.op, step.correction
        # 3. behaviour: the command, following the path around what the scan sees (farther
        #    from what the map does not explain: other robots, people)
        pts = scan_to_points(
            scan, self.cfg.slam.frontier_range_m, self._mount(), motion=motion
        )  # de-skewed too: a TurtleBot3 turning at 2.8 rad/s sweeps 0.57 rad per scan
        xy = pts.xy[pts.valid]
        world = transform_points(self.pose, xy)
        self._remember_unmapped(stamp_s, world)
        out.assignment = self._own_target(stamp_s)
        obstacles, moving = self._obstacles(stamp_s, odom, xy, world)
        out.cmd = self._guarded(
            self.behaviour.step(stamp_s, self.pose, obstacles, moving, turned), obstacles
        )
        self.follower.sent(*out.cmd)  # arcs start from what the base does
        # 4. pose and state for the coordinator
        if stamp_s - self._last_pose_t >= POSE_PERIOD_S or step.delta is not None:
            self._last_pose_t = stamp_s
            blocked_by = self.behaviour.blocked_by
            clear = b""
            if self._sighting_wanted() and stamp_s - self._last_clear_t >= PROFILE_PERIOD_S:
                self._last_clear_t = stamp_s
                clear = self._clear_profile(scan, xy)
            out.pose = Pose(
                *map(float, self.pose),
                self.slam.map.version,
                blocked_by,
                self.frame,
                clear,
                self.own_frame,
            )
        if self.behaviour.changed or stamp_s - self._last_status_t >= STATUS_PERIOD_S:
            self._last_status_t = stamp_s
            self.behaviour.changed = False
            out.status = self.status()
        return out

    def _sighting_wanted(self) -> bool:
        """Whether a robot of the swarm started in a frame of its own: the coordinator
        then wants the clear profiles that tell its frame's images apart, and, once it
        is merged, that audit its frame (``agents.anchoring``): 128 bytes a second."""
        if self.sightings is not None:
            return self.sightings
        return bool(self._own_frames)

    def _clear_profile(self, scan: LaserScan, returns: np.ndarray) -> bytes:
        """``polyswarm.frames.sighting.clear_profile`` of this scan (``returns``: its de-skewed
        returns in the robot frame)."""
        valid, no_return, _ = classify(scan, self.cfg.sim.lidar.out_of_range)
        blind = beam_angles(scan, self._mount())[~valid & ~no_return]
        return clear_profile(returns, blind)

    def _remember_unmapped(self, stamp_s: float, world: np.ndarray) -> None:
        """Close returns (world frame; other robots left out) that the planning map does
        not hold: the planner keeps clear of them (``agents.seen``)."""
        self._now_s = stamp_s
        pmap = self.merged if self.merged is not None else self.slam.map
        self.seen.forget_seen_through(world, self.pose[:2])
        keep = ~self._near_peers(world, stamp_s)
        self.seen.add(stamp_s, world[keep], self.pose[:2], pmap)

    def _guarded(self, cmd: tuple[float, float], obstacles: np.ndarray) -> tuple[float, float]:
        """To a real base through ``cmd_vel`` (output "twist"): no translation towards a
        return in the way, within the speed limits (``polyswarm.nav.guard``)."""
        io = self.cfg.agent
        if io.output != CommandOutput.TWIST:
            return cmd
        base = self.cfg.sim.robot
        return guard(
            *cmd,
            obstacles,
            self.cfg.nav.robot_radius_m,
            io.stop_distance_m,
            io.max_linear_mps or base.max_linear_mps,
            io.max_angular_radps or base.max_angular_radps,
        )

    def on_coordinator_alive(self, name: str, alive: bool) -> None:
        self.alone.coordinator(name, alive, self._now_s)

    def _own_target(self, now_s: float) -> Assignment | None:
        """Alone with nothing to do: a frontier of its own map (``agents.alone``)."""
        if not self.alone.wants_target(now_s, self.state, self.assignment):
            return None
        if not self.alone.due(now_s):
            return None
        own, graph = self._planning_map()

        def plan(goal):
            try:
                return self.plan(self.pose[:2], goal, partial=False)
            except PlanningError:
                return None

        peers = [xy for _, xy in self.peers.values()]
        a = self.alone.choose(
            own,
            graph,
            self.merged,
            Sensor.of(self.cfg.sim.lidar),
            self.pose[:2],
            peers,
            plan,
            self.assignment,
        )
        if a is not None:
            self.behaviour.on_assignment(a, now_s, self.pose)
        return a

    def _obstacles(self, stamp_s: float, odom, xy: np.ndarray, world: np.ndarray):
        """What the controller keeps clear of, (n, 2) in the robot frame, and which of it
        the map does not explain: this scan's returns and the last seconds' close ones
        (``polyswarm.nav.recent``: a dark wall returns a few beams per scan), other
        robots' left out of the memory (they move)."""
        keep = ~self._near_peers(world, stamp_s)
        self.recent.add(stamp_s, odom, xy[keep])
        remembered = self.recent.points(stamp_s, odom)
        moving = np.concatenate([self._unexplained(world), np.zeros(len(remembered), bool)])
        return np.concatenate([xy, remembered]), moving

    def _unexplained(self, world: np.ndarray) -> np.ndarray:
        """Scan points (world frame) farther than ``UNEXPLAINED_M`` from every obstacle
        vector of the robot's own map: something that moves, or not mapped yet."""
        if len(world) == 0:
            return np.zeros(0, dtype=bool)
        m = self.slam.map
        st, en, _ = m.vectors([VectorType.OBSTACLE], m.cells_within(*self.pose[:2], NEAR_M))
        return clear_of(world, st, en, UNEXPLAINED_M)

    def _mount(self):
        m = self.cfg.slam.mount
        return (m.x_m, m.y_m, m.yaw_rad, m.upside_down)

    def use_tf_mount(self, found) -> None:
        """The lidar's mount from the robot's tf (``protocols.tf.MountSources``, or
        None: nothing new), unless the config sets one; without either, said once after
        ``MOUNT_WAIT_SCANS`` scans."""
        from protocols.tf import TF, TF_STATIC, choose_mount

        if found is None:
            if (
                self.cfg.agent.source != SensorSource.NATIVE
                and self.stats.scans == MOUNT_WAIT_SCANS
                and not self._mount_said
            ):
                self._mount_said = True
                choose_mount(self.cfg.slam.mount, None, self.id)
            return
        mount, source = choose_mount(self.cfg.slam.mount, found, self.id)
        if source in (TF_STATIC, TF):
            if self.stats.scans:
                log.warning("%s: the mount from tf came after %d scans", self.id, self.stats.scans)
            self.cfg = replace(self.cfg, slam=replace(self.cfg.slam, mount=mount))
            self.slam.cfg = replace(self.slam.cfg, mount=mount)
        self._mount_said = True

    def status(self) -> RobotStatus:
        b = self.behaviour
        return RobotStatus(
            b.state,
            -1 if b.assignment is None else b.assignment.target,
            b.detail[:200],
            self.slam.keyframes,
            self.slam.map.version,
            self.bytes_sent,
            self.stats.distance_m,
            self.path_left(),
        )

    def path_left(self) -> tuple[tuple[float, float], ...]:
        """The planned path from the robot on, at most MAX_STATUS_PATH_POINTS points (cm)."""
        path = self.follower.path
        if path is None or len(path) == 0:
            return ()
        rest = np.vstack([self.pose[:2], path[self.follower.progress + 1 :]])
        if len(rest) > MAX_STATUS_PATH_POINTS:
            keep = np.linspace(0, len(rest) - 1, MAX_STATUS_PATH_POINTS).round().astype(int)
            rest = rest[keep]
        return tuple((round(float(x), 2), round(float(y), 2)) for x, y in rest)

    # -- what the behaviour asks (agents.behaviour.Planning) ------------------------------

    def plan(self, start: np.ndarray, goal: np.ndarray, partial: bool):
        """A path on the merged map (the robot's own before it has one)."""
        pmap, graph = self._planning_map()
        return Planner(pmap, graph, self.seen.points(self._now_s)).plan(
            start, goal, partial=partial
        )

    def yield_point(self, xy: np.ndarray, other: np.ndarray) -> np.ndarray | None:
        """A free point about a metre from ``xy``, away from the other robot."""
        away = xy - other
        base = math.atan2(away[1], away[0])
        m = self.slam.map
        st, en, _ = m.vectors(
            [VectorType.OBSTACLE, VectorType.FRONTIER], m.cells_within(*xy, NEAR_M)
        )
        for turn in (0.0, 0.6, -0.6, 1.2, -1.2, 1.8, -1.8):
            for dist in (1.0, 0.6):
                a = base + turn
                p = xy + dist * np.array([math.cos(a), math.sin(a)])
                if m.is_free(*p) and clear_of(p[None, :], st, en, self.radius)[0]:
                    return p
        return None

    def look_done(self) -> None:
        self.slam.request_keyframe()  # what it sees now goes into the map

    def _planning_map(self) -> tuple[GridPolyMap, NavGraph]:
        """The merged map; the robot's own before it has one, or while it is alone (the
        merged map stops growing then)."""
        alone = self.alone.active(self._now_s)
        if self.merged is not None and self.merged_graph is not None and not alone:
            return self.merged, self.merged_graph
        own = self.slam.map
        if self.own_graph is None or self._own_graph_version != own.version:
            self.own_graph = NavGraph.for_robot(own, self.cfg.nav)
            self._own_graph_version = own.version
        return own, self.own_graph


def scan_from_message(msg: Scan, stamp_s: float) -> LaserScan:
    return LaserScan(
        msg.ranges_m,
        msg.angle_min_rad,
        msg.angle_increment_rad,
        msg.range_min_m,
        msg.range_max_m,
        stamp_s,
        msg.time_increment_s,
        msg.scan_time_s,
    )


def scan_end_s(item) -> float:
    """When a scan message's last beam was taken: its points need odometry until then."""
    msg: Scan = item.msg
    return item.stamp_s + msg.time_increment_s * max(len(msg.ranges_m) - 1, 0)
