"""The sections of the configuration (``polyswarm.config``): frozen dataclasses whose
every number carries its physical range (``num``, ``positive``), checked when loaded."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum

from polyswarm.profiles import DEFAULT_PROFILE

# ---------------------------------------------------------------------------------------
# Physical ranges: every number of the configuration has one, checked when it is loaded
# ---------------------------------------------------------------------------------------

TWO_PI = 2 * math.pi


@dataclass(frozen=True)
class Range:
    """Allowed values of a numeric field: lo..hi, each end open or closed."""

    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False

    def contains(self, v: float) -> bool:  # NaN is outside every range
        above = v > self.lo if self.lo_open else v >= self.lo
        below = v < self.hi if self.hi_open else v <= self.hi
        return bool(above and below)

    def describe(self) -> str:
        left, right = "(" if self.lo_open else "[", ")" if self.hi_open else "]"
        return f"{left}{self.lo:g}, {self.hi:g}{right}"


def num(default: float, lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False):
    """A float or int field with its physical range."""
    return field(default=default, metadata={"range": Range(lo, hi, lo_open, hi_open)})


def positive(default: float, hi: float):
    """A field that must be above zero (a length, a rate, a standard deviation...)."""
    return num(default, 0.0, hi, lo_open=True)


# ---------------------------------------------------------------------------------------
# Sections
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MapConfig:
    """PolyMap storage (chapter 3.1 and 4.5 of the thesis)."""

    # Side of the square cells the map is stored on; also the unit of a delta. 2 m was
    # chosen by `polyswarm bench cells` (merge cost against delta bytes, see README).
    cell_size_m: float = num(2.0, 0.1, 100.0)
    # Whole maps that are shared or saved (the coordinator's map replies, .polymap files)
    # have their vertices rounded to this grid: a third smaller than the map's own 10 um
    # (`polyswarm bench bandwidth`), and 50 times finer than a 5 cm occupancy grid
    whole_map_precision_m: float = num(0.001, 1e-5, 0.01)


class OutOfRange(StrEnum):
    """How a lidar driver reports a beam that saw nothing within its range."""

    INF = "inf"  # +inf (REP 117; rplidar_ros, Hokuyo's urg_node)
    NAN = "nan"
    ZERO = "zero"  # 0.0 (the TurtleBot3 LDS-01 driver), the same value as a dropout


@dataclass(frozen=True)
class LidarConfig:
    """The robot's 2D lidar: simulated as given, and read by exploration (its range and
    field of view). Defaults are the thesis simulations' sensor (chapter 5.3); a named
    profile (``polyswarm.profiles``) sets all of it."""

    fov_rad: float = num(4.71238898038469, 0.0, TWO_PI, lo_open=True)  # 270 degrees
    beams: int = num(720, 2, 100_000)
    range_max_m: float = positive(30.0, 1000.0)
    range_min_m: float = num(0.05, 0.0, 100.0)
    rate_hz: float = positive(10.0, 1000.0)
    # zero-mean Gaussian range noise: std noise_sigma_m + noise_sigma_per_m x range
    noise_sigma_m: float = num(0.01, 0.0, 1.0)
    noise_sigma_per_m: float = num(0.0, 0.0, 0.2)
    # How the lidar fails (``sim.lidar.measure``; the profiles' figures are fitted to real
    # recordings, ``polyswarm bench lidar``). A beam that meets a surface at range r and
    # incidence a (from the surface's normal) returns nothing with probability
    #   1 - (1 - p_range) (1 - p_incidence), p_range rising from dropout_prob near the
    #   sensor to dropout_far_prob at range_max (a logistic step at dropout_far_from share
    #   of range_max), p_incidence = dropout_grazing_prob x ((a - 45 deg) / 35 deg)^2 above
    #   45 degrees (1 from 80);
    # a dark or glass surface with dark_dropout_prob; dropouts come in runs of about
    # dropout_run_beams (correlated along the sweep); at an edge between two surfaces a
    # return falls between them with mixed_pixel_prob
    dropout_prob: float = num(0.0, 0.0, 1.0, hi_open=True)
    dropout_far_prob: float = num(0.0, 0.0, 1.0, hi_open=True)
    dropout_far_from: float = num(0.5, 0.0, 1.0)
    dropout_grazing_prob: float = num(0.0, 0.0, 1.0)
    dark_dropout_prob: float = num(0.0, 0.0, 1.0)
    dropout_run_beams: float = num(1.0, 1.0, 1000.0)
    mixed_pixel_prob: float = num(0.0, 0.0, 1.0)
    out_of_range: str = "inf"  # OutOfRange: how a beam with no return is reported
    # the beams of a scan are taken one after the other over the sweep (1 / rate_hz) while
    # the robot moves, as a spinning lidar does; false: all at one instant
    rolling: bool = False
    height_m: float = num(0.2, 0.0, 0.99, lo_open=True)  # ray height, below the walls' 1 m


@dataclass(frozen=True)
class OdometryNoiseConfig:
    """Wheel-odometry noise of the simulator.

    A random walk per integration step whose variances grow linearly with distance and
    rotation (so drift does not depend on the step: the std of the travelled-distance
    error after d metres is ``trans_sigma_per_sqrt_m * sqrt(d)``), plus systematic
    errors drawn once per robot: every distance scaled by 1 + N(0, scale_sigma) (a wheel
    radius off), every turn by 1 + N(0, turn_scale_sigma) (the wheel base off).
    """

    trans_sigma_per_sqrt_m: float = num(0.01, 0.0, 1.0)  # m/sqrt(m): along-track distance
    lateral_sigma_per_sqrt_m: float = num(0.005, 0.0, 1.0)  # m/sqrt(m): sideways slip
    rot_sigma_per_sqrt_rad: float = num(0.01, 0.0, 1.0)  # rad/sqrt(rad): heading from turning
    rot_sigma_per_sqrt_m: float = num(0.005, 0.0, 1.0)  # rad/sqrt(m): heading from driving
    scale_sigma: float = num(0.0, 0.0, 0.5)  # fraction: distance scale error per robot
    turn_scale_sigma: float = num(0.0, 0.0, 0.5)  # fraction: turn scale error per robot


@dataclass(frozen=True)
class RobotConfig:
    radius_m: float = positive(0.2, 5.0)
    max_linear_mps: float = positive(0.5, 20.0)
    max_angular_radps: float = positive(1.5, 20.0)
    max_linear_accel_mps2: float = positive(1.0, 100.0)
    max_angular_accel_radps2: float = positive(3.0, 100.0)


@dataclass(frozen=True)
class SimConfig:
    world: str = "office"
    seed: int = num(0, 0, 2**32 - 1)
    physics_hz: float = num(50.0, 1.0, 10_000.0)  # fixed integration step of the robots
    # simulated seconds per wall-clock second when serving (0: as fast as possible)
    speed: float = num(10.0, 0.0, 1e6)
    # pybullet rayTestBatch threads: 0 = every core (rays are independent, so the scans
    # stay bit-identical; 1.3-1.7x faster on 2 cores), 1 = the caller's thread only.
    raycast_threads: int = num(0, 0, 256)
    # share of the walls' length that is glass or black (doors, cabinets, furniture), in
    # stretches of 0.5-2 m drawn per world from the seed; each lidar profile says how
    # often it sees them (sim.lidar.dark_dropout_prob)
    dark_surface_share: float = num(0.1, 0.0, 1.0)
    robot: RobotConfig = field(default_factory=RobotConfig)
    lidar: LidarConfig = field(default_factory=LidarConfig)
    odometry_noise: OdometryNoiseConfig = field(default_factory=OdometryNoiseConfig)
    # where the simulated robots really start (world frame: x m, y m, theta rad), one per
    # [[robots]] entry; empty: at their [[robots]] starts. For robots whose start poses
    # the swarm is not told (``launch --unknown-start``): only the simulator knows these
    start_poses: tuple[tuple[float, float, float], ...] = ()


@dataclass(frozen=True)
class RefineConfig:
    """Polygon refinement by line fitting (thesis 3.5, Algorithm 3, formulas 3.5-3.9)."""

    inlier_threshold_m: float = positive(0.03, 1.0)
    score_a: float = num(1.0, 0.0, 1000.0)
    score_b: float = num(4.0, 0.0, 1000.0)
    score_c: float = positive(0.001, 1000.0)  # avoids a division by zero
    flat_angle_deg: float = num(15.0, 0.0, 90.0)  # below this, chains meet flat: no intersection
    flat_merge_distance_m: float = num(0.01, 0.0, 1.0)  # projections closer are averaged
    # > 0: scan points farther than this from the result are pinned (visited by the
    # polygon). Off for mapping: pinning 3-sigma noise points makes spikes that bias ICP.
    max_point_error_m: float = num(0.0, 0.0, 1.0)


@dataclass(frozen=True)
class IcpConfig:
    max_iterations: int = num(30, 1, 1000)
    # initial outlier threshold (thesis Table 5.3: 0.2 - 1.0)
    outlier_start_m: float = positive(0.5, 10.0)
    outlier_end_m: float = positive(0.03, 10.0)  # after shrinking (3 sigma of the thesis' lidar)
    shrink: float = num(0.6, 0.0, 1.0, lo_open=True)  # threshold times this every iteration
    tolerance_m: float = positive(1e-4, 1.0)  # converged when the update moves points less
    backface_culling: bool = True
    sample_spacing_m: float = positive(0.05, 1.0)  # map obstacle vectors sampled this often
    degeneracy_ratio: float = num(0.02, 0.0, 1.0)  # eigenvalue ratio below which an axis is free
    map_radius_m: float = positive(32.0, 1000.0)  # obstacle vectors farther away are ignored
    rotation_search_rad: float = num(0.35, 0.0, math.pi)  # heading pre-alignment (0: off)


class IcpReference(StrEnum):
    KEYFRAMES = "keyframes"  # obstacle vectors of the nearby keyframes (polyswarm.slam.submap)
    MAP = "map"  # obstacle vectors of the merged PolyMap (the thesis' choice)


@dataclass(frozen=True)
class SubmapConfig:
    """Which keyframes a scan is matched against (polyswarm.slam.submap)."""

    reference: str = "keyframes"  # IcpReference
    keyframes: int = num(20, 0, 10_000)  # at most this many keyframes nearest the prediction...
    radius_m: float = positive(10.0, 1000.0)  # ...within this distance of it...
    recent: int = num(5, 1, 10_000)  # ...plus always the latest few (tracking is sure of them)


@dataclass(frozen=True)
class LoopClosureConfig:
    """Loop edges and pose-graph optimisation (polyswarm.slam.posegraph)."""

    enabled: bool = True
    # a loop joins keyframes at least this many keyframes apart
    min_age_keyframes: int = num(30, 1, 1_000_000)
    radius_m: float = num(5.0, 0.0, 1000.0)  # old keyframes this close to the pose are matched
    keyframes: int = num(10, 1, 10_000)  # the old submap: at most this many keyframes
    min_inlier_fraction: float = num(0.5, 0.0, 1.0)  # of the scan's valid points
    max_rmse_m: float = positive(0.05, 1.0)  # point-to-vector RMSE of an accepted loop match
    max_correction_m: float = num(2.0, 0.0, 100.0)  # a loop moving the pose more is refused
    search_window_m: float = num(2.0, 0.0, 100.0)  # wide search (polyswarm.slam.loopsearch)...
    search_every_keyframes: int = num(5, 1, 1_000_000)  # ...at most this often, not after a loop
    # the window grows with the distance driven since the last loop (drift grows with it;
    # 2-3 % on the logs' noise), up to max_search_window_m; 0: fixed
    search_window_per_m: float = num(0.03, 0.0, 1.0)
    max_search_window_m: float = num(5.0, 0.0, 100.0)
    optimise_above_m: float = num(0.02, 0.0, 10.0)  # a loop correction (heading at 2 m per rad)
    tracking_sigma_m: float = positive(0.05, 10.0)  # std of a sequential edge from ICP
    tracking_sigma_rad: float = num(0.01, 0.0, math.pi, lo_open=True)
    # ... or this many times ICP's own heading std (IcpResult.heading_sigma_rad), if more:
    # that std counts scan noise only; on orebro and aces the tracking edges' heading errors
    # were a median 6 and a 90th percentile 20 times it
    heading_sigma_inflation: float = num(20.0, 1.0, 1000.0)
    odometry_sigma_m: float = positive(0.2, 10.0)  # std of a sequential edge where ICP failed
    odometry_sigma_rad: float = num(0.05, 0.0, math.pi, lo_open=True)
    loop_sigma_m: float = positive(0.05, 10.0)
    loop_sigma_rad: float = num(0.01, 0.0, math.pi, lo_open=True)

    def search_window(self, travel_m: float) -> float:
        """The wide search's window (metres) after driving ``travel_m`` since the last loop."""
        grown = max(self.search_window_m, self.search_window_per_m * travel_m)
        return min(grown, max(self.max_search_window_m, self.search_window_m))


@dataclass(frozen=True)
class LidarMount:
    """Where the lidar sits on the robot (robot frame), and whether it is upside down."""

    x_m: float = num(0.0, -10.0, 10.0)
    y_m: float = num(0.0, -10.0, 10.0)
    yaw_rad: float = num(0.0, -TWO_PI, TWO_PI)
    upside_down: bool = False  # mirrored scans: beam angles run clockwise


@dataclass(frozen=True)
class EvidenceConfig:
    """The evidence behind the map (``polyswarm.slam.evidence``): every scan counted per
    cell, and each keyframe polygon made as the view of those counts from its lidar.
    For lidars that lose beams in runs (the low-cost ones labs own, and real recordings,
    which ``polyswarm slam BAG`` always reads so); off for the thesis's clean sensor."""

    enabled: bool = False
    resolution_m: float = num(0.05, 0.01, 0.5)  # the evidence grid's cell
    # view rays per lidar beam: more finds small obstacles between the beams at range
    oversample: int = num(2, 1, 8)


@dataclass(frozen=True)
class SlamConfig:
    keyframe_distance_m: float = positive(0.4, 100.0)
    keyframe_angle_rad: float = num(0.3490658503988659, 0.0, TWO_PI, lo_open=True)  # 20 deg
    # ... or sooner, when this share of a scan's beams end in unexplored space (a robot
    # passing a door sees a room a little differently at every step; keyframes every
    # 0.4 m left wedges of it unseen between their fans). 0: off
    keyframe_novelty: float = num(0.0, 0.0, 1.0)
    frontier_range_m: float = positive(0.2, 100.0)  # dropouts become frontier points here
    # a beam with no return within the lidar's range crossed free space: it ends this far
    # out (Cartographer's missing_data_ray_length), or at NO_RETURN_SHARE of the range if
    # that is less (polyswarm.slam.scan). At 0.2 m a robot turning on the spot stood in the
    # apex of unknown wedges with no room to plan; at 1 m a TurtleBot3 (3.5 m lidar)
    # looking into a room through its door saw no farther than the door, and three robots
    # ended the office at 38 % coverage (2.8 m: 99 % in 220-245 s, seeds 0-1)
    no_return_free_m: float = positive(4.0, 100.0)
    # merging keyframes (polyswarm.polymap.MergeOptions)
    notch_fill_m: float = num(0.01, 0.0, 1.0)  # walls smoothed across keyframes
    min_growth_m: float = num(0.05, 0.0, 1.0)  # new explored space thinner is noise along walls
    obstacle_snap_m: float = num(0.05, 0.0, 1.0)  # a frontier this close along a wall is it
    # a frontier lying all along beside a wall, at most this far inside it or in front of
    # it, is that wall (the chord of a grazing view of a face another view saw head-on).
    # On the maze, robots were sent to look at such faces, 2-5 cm off, and looking did not
    # close them. Inside: thinner than walls. In front: more than min_growth_m plus noise
    obstacle_snap_behind_m: float = num(0.1, 0.0, 0.5)
    obstacle_snap_front_m: float = num(0.08, 0.0, 0.5)
    # keyframe polygons are merged with their vertices on this grid, so that a robot can
    # send the polygon itself as its map delta, in whole millimetres, and the receiver
    # replays the merge bit for bit (polymap.MergeOp); 1 mm is far below lidar noise.
    # 0: not snapped, and deltas go as changed cells
    merge_quantum_m: float = num(0.001, 0.0, 0.05)
    # a keyframe is merged (and sent) with the stretches that cannot change the map
    # replaced by chords (polyswarm.slam.trim): 8-17 % fewer bytes sent on the shared logs
    trim_merges: bool = True
    # after a loop closure, the cells of keyframes it moved are merged again at their
    # new poses (polyswarm.slam.follow), and the correction goes to the coordinator as poses
    # (PROTOCOL.md 3.5): the shared map loses the ghosts of the pose errors made before
    # the loop closed (ACES, real odometry: 58 % ghost walls -> 0.8 %). The cost: one
    # correction's p95 is 0.4-1.6 s on the logs (polyswarm bench slam)
    map_follows_graph: bool = True
    # the odometry's distance scale (a wheel radius off) is learnt from keyframes ICP
    # pinned down and corrected where ICP keeps the odometry (polyswarm.slam.odomscale). Off:
    # with the TurtleBot3's 3.5 m lidar the learnt scale was up to 1.8 % wrong and 3-robot
    # office runs gained nothing measurable; on in the
    # thesis-noisy-odometry profile, where the 30 m lidar makes it right to 0.5 %
    learn_odometry_scale: bool = False
    obstacle_max_gap_m: float = positive(0.5, 100.0)  # points farther apart: a frontier...
    obstacle_gap_beams: float = num(4.0, 0.0, 1000.0)  # ...unless this many beam spacings
    # rebuild_map (offline runs, after loop closures) merges this many consecutive
    # keyframes in one pass: they overlap, so a pass costs little more than one merge.
    # The maze route's 3,296 keyframes: 76 s one by one, 23 s by 8 (IoU 0.996 both, mean
    # wall distance 12.7 -> 13.5 mm, obstacle vectors 3,748 -> 4,334); 1: one by one
    rebuild_batch: int = num(8, 1, 10_000)
    icp: IcpConfig = field(default_factory=IcpConfig)
    submap: SubmapConfig = field(default_factory=SubmapConfig)
    loop_closure: LoopClosureConfig = field(default_factory=LoopClosureConfig)
    refine: RefineConfig = field(default_factory=RefineConfig)
    mount: LidarMount = field(default_factory=LidarMount)
    evidence: EvidenceConfig = field(default_factory=EvidenceConfig)


@dataclass(frozen=True)
class NavConfig:
    robot_radius_m: float = positive(0.2, 5.0)
    # extra distance kept from map obstacles when planning: covers the map's wall error
    # (about 3 cm, bench slam) and leaves the local controller (which keeps the radius
    # plus ControlParams.safety_margin_m from scan points) room to follow the path
    clearance_margin_m: float = num(0.1, 0.0, 5.0)
    # distance the planned path keeps from frontier vectors (the edge of explored space),
    # 0 to robot_radius_m + clearance_margin_m. Beyond a frontier nothing is known, not a
    # wall; the local controller keeps its distance from whatever the live scan shows
    # there. With the full clearance, a door seen at an angle let no robot in (see
    # polyswarm.nav.navgraph)
    frontier_clearance_m: float = num(0.1, 0.0, 10.0)
    # where nothing wider leads on (a door 0.7 m wide for a 0.4 m robot), the path may keep
    # only this much beyond the radius from mapped obstacles: the map's wall error. Such
    # tight passages cost navgraph.TIGHT_PENALTY_M more, so wider ways are preferred
    tight_margin_m: float = num(0.03, 0.0, 5.0)

    @property
    def obstacle_clearance_m(self) -> float:
        """Distance the planned path keeps from obstacle vectors."""
        return self.robot_radius_m + self.clearance_margin_m

    @property
    def tight_clearance_m(self) -> float:
        """... and in a tight passage."""
        return self.robot_radius_m + self.tight_margin_m


class Strategy(StrEnum):
    """How the coordinator assigns frontier targets (polyswarm.explore.assign.assign)."""

    HUNGARIAN = "hungarian"
    GREEDY = "greedy"
    NEAREST = "nearest"


@dataclass(frozen=True)
class ExploreConfig:
    strategy: str = "hungarian"  # Strategy
    min_frontier_length_m: float = num(0.4, 0.0, 100.0)  # shorter segments are not targets
    max_frontier_length_m: float = positive(4.0, 1000.0)  # longer ones are split for sharing
    blacklist_after_failures: int = num(2, 1, 1000)
    # a robot stood at the goal, within sensor range, and looked, yet the frontier stayed
    # open where it was: after this many such looks it is a frontier that looking does not
    # close (mostly wall faces seen at a grazing angle). A look that moves the frontier on
    # is not one of them (agents.allocation.LOOK_MOVED_M)
    blacklist_after_looks: int = num(2, 1, 1000)
    no_progress_timeout_s: float = positive(20.0, 1e5)  # path cost must shrink within this
    hysteresis: float = num(0.8, 0.0, 1.0, lo_open=True)  # a new target must cost less than
    #                                                       this times the current one
    target_separation_m: float = num(3.0, 0.0, 1000.0)  # targets of robots this far apart
    cycle_period_s: float = positive(1.0, 3600.0)  # assignment cycle (also on events)
    end_confirm_s: float = num(3.0, 0.0, 3600.0)  # no reachable frontier this long: done
    return_home: bool = True  # robots drive back to their start when the mission ends
    # processes that replay the robots' merges and corrections for the coordinator, off
    # its thread (agents.replay); 0 replays them on it. With 25 robots one process ran
    # 1.7 s behind on a 2-core machine (bench cycle): give a fleet of tens more, up to
    # one per spare core
    replay_workers: int = num(1, 0, 64)
    # merge robots' cells into the merged map, update its navigation graph and frontier
    # facts on a process of its own (agents.merger), while the coordinator plans on the
    # map it has; false: on its thread
    merge_process: bool = True
    # robots correct each other: the coordinator's joint pose graph over every robot's
    # keyframes sends priors where one robot's walls align on another's
    # (polyswarm.frames.jointgraph); false: each robot corrects only itself
    joint_graph: bool = True


@dataclass(frozen=True)
class RobotEntry:
    """A robot of the swarm and its start pose in the shared map frame (x m, y m,
    theta rad). Left out: not known. The robot then maps in a frame of its own until the
    coordinator finds where that frame lies by matching its map with the merged map
    (``polyswarm.frames.mapmatch``); when no robot's start is given, the first robot's start
    is the shared frame's origin (``known_starts``)."""

    id: str = "r1"
    start: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class CommsConfig:
    swarm: str = "default"
    endpoint: str = "tcp/127.0.0.1:7447"
    zenoh_config: str = ""  # optional path to a Zenoh JSON5 config file


class SensorSource(StrEnum):
    NATIVE = "native"  # polyswarm Scan and Odometry messages (the simulator, log replay)
    ROS2 = "ros2"  # sensor_msgs/LaserScan and nav_msgs/Odometry CDR (zenoh-bridge-ros2dds)
    RMW_ZENOH = "rmw_zenoh"  # the same, from a robot whose ROS 2 runs on rmw_zenoh (no bridge)
    ROS2_NODE = "ros2-node"  # a node of the robot's ROS 2 graph (rclpy): map and markers out


class CommandOutput(StrEnum):
    NATIVE = "native"  # polyswarm CmdVel messages (the simulator)
    TWIST = "twist"  # geometry_msgs/Twist CDR on cmd_vel_key
    GOAL = "goal"  # geometry_msgs/PoseStamped of the assigned goal on goal_key (own nav stack)
    # source "ros2-node": Nav2's navigate_to_pose action (nav2_action_key); its outcome
    # ends the target or tells the coordinator it failed
    NAV2 = "nav2"
    NONE = "none"  # drive nothing (log replay, mapping only)


@dataclass(frozen=True)
class AgentIoConfig:
    """Where a robot agent reads its sensors and sends its commands.

    ``{ns}`` in a key is replaced by ``namespace``. With zenoh-bridge-ros2dds started as
    ``-n /tb3_1`` on a robot whose topics are not namespaced, its ``/scan`` is the key
    ``tb3_1/scan`` (namespace "tb3_1"); the bridge prepends its namespace to every topic,
    so a robot that already publishes ``/tb3_1/scan`` through a bridge with ``-n /tb3_1``
    is on ``tb3_1/tb3_1/scan``. With ``source = "rmw_zenoh"`` the keys are a topic name
    (``namespace`` + the key) in rmw_zenoh's format (``protocols.rmw_zenoh``)."""

    source: str = "native"  # SensorSource
    output: str = "native"  # CommandOutput
    namespace: str = ""
    scan_key: str = "{ns}/scan"
    odom_key: str = "{ns}/odom"
    tf_static_key: str = "{ns}/tf_static"  # the lidar's mount, unless [slam.mount] sets one
    # source "ros2-node": the mount from here too (as ROS 1 setups publish it), and the
    # map -> odom transform out
    tf_key: str = "{ns}/tf"
    cmd_vel_key: str = "{ns}/cmd_vel"
    goal_key: str = "{ns}/goal_pose"
    nav2_action_key: str = "{ns}/navigate_to_pose"  # output "nav2": Nav2's action
    map_frame: str = "map"  # frame id of goals sent to the robot's navigation stack
    # output "twist": no translation towards a return closer than this beyond the robot's
    # body (metres; the controller keeps 0.03 m more), and the speed limits (0: the
    # profile's base)
    stop_distance_m: float = num(0.02, 0.0, 1.0)
    max_linear_mps: float = num(0.0, 0.0, 5.0)
    max_angular_radps: float = num(0.0, 0.0, 10.0)
    # rmw_zenoh: the robot's ROS_DOMAIN_ID (the first chunk of its keys), 0-232: ROS 2's range
    domain_id: int = num(0, 0, 232)

    def key(self, template: str) -> str:
        return template.replace("{ns}", self.namespace).strip("/")


@dataclass(frozen=True)
class PersistConfig:
    """Where agents and the coordinator keep their maps across restarts ("": nowhere)."""

    dir: str = ""


@dataclass(frozen=True)
class Config:
    # the robot (polyswarm.profiles): its values of sim.lidar, sim.robot,
    # sim.odometry_noise and nav.robot_radius_m, under anything set explicitly
    profile: str = DEFAULT_PROFILE
    map: MapConfig = field(default_factory=MapConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    slam: SlamConfig = field(default_factory=SlamConfig)
    nav: NavConfig = field(default_factory=NavConfig)
    explore: ExploreConfig = field(default_factory=ExploreConfig)
    comms: CommsConfig = field(default_factory=CommsConfig)
    agent: AgentIoConfig = field(default_factory=AgentIoConfig)
    persist: PersistConfig = field(default_factory=PersistConfig)
    robots: tuple[RobotEntry, ...] = ()  # [[robots]] tables: ids and start poses
