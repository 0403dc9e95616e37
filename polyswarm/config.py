"""One typed, nested configuration object, loaded from TOML and passed explicitly.

Every section is a frozen dataclass; unknown keys are rejected with a "did you mean"
hint; values are type-checked. The effective configuration is written next to the
results of every run (``save_config``).

    cfg = load_config("robot.toml")          # or Config() for the defaults
    cfg = with_overrides(cfg, {"slam": {"keyframe_distance_m": 0.3}})
"""

from __future__ import annotations

import dataclasses
import difflib
import tomllib
import types
import typing
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

from polyswarm.errors import ConfigError

# ---------------------------------------------------------------------------------------
# Sections
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MapConfig:
    """PolyMap storage (chapter 3.1 and 4.5 of the thesis)."""

    # Side of the square cells the map is stored on; also the unit of a delta. 2 m was
    # chosen by `polyswarm bench cells` (merge cost against delta bytes, see README).
    cell_size_m: float = 2.0
    # Whole maps that are shared or saved (the coordinator's map replies, .polymap files)
    # have their vertices rounded to this grid: a third smaller than the map's own 10 um
    # (`polyswarm bench bandwidth`), and 50 times finer than a 5 cm occupancy grid
    whole_map_precision_m: float = 0.001


@dataclass(frozen=True)
class LidarConfig:
    """A 2D lidar. Defaults are the thesis simulations' sensor (chapter 5.3)."""

    fov_rad: float = 4.71238898038469  # 270 degrees
    beams: int = 720
    range_max_m: float = 30.0
    range_min_m: float = 0.05
    rate_hz: float = 10.0
    noise_sigma_m: float = 0.01  # zero-mean Gaussian range noise
    dropout_prob: float = 0.0  # probability that a beam returns NaN
    height_m: float = 0.2  # ray height above the floor in the simulator


@dataclass(frozen=True)
class OdometryNoiseConfig:
    """Wheel-odometry noise of the simulator, per integration step.

    Variances grow linearly with distance and rotation, so drift does not depend on the
    integration step: std of the travelled-distance error after d metres is
    ``trans_sigma_per_sqrt_m * sqrt(d)``.
    """

    trans_sigma_per_sqrt_m: float = 0.01  # m/sqrt(m): along-track distance error
    lateral_sigma_per_sqrt_m: float = 0.005  # m/sqrt(m): sideways slip
    rot_sigma_per_sqrt_rad: float = 0.01  # rad/sqrt(rad): heading error from turning
    rot_sigma_per_sqrt_m: float = 0.005  # rad/sqrt(m): heading error from driving


@dataclass(frozen=True)
class RobotConfig:
    radius_m: float = 0.2
    max_linear_mps: float = 0.5
    max_angular_radps: float = 1.5
    max_linear_accel_mps2: float = 1.0
    max_angular_accel_radps2: float = 3.0


@dataclass(frozen=True)
class SimConfig:
    world: str = "office"
    seed: int = 0
    physics_hz: float = 50.0  # fixed integration step of the robots
    speed: float = 10.0  # simulated seconds per wall-clock second when serving
    # pybullet rayTestBatch threads: 0 = every core (rays are independent, so the scans
    # stay bit-identical; 1.3-1.7x faster on 2 cores), 1 = the caller's thread only.
    raycast_threads: int = 0
    robot: RobotConfig = field(default_factory=RobotConfig)
    lidar: LidarConfig = field(default_factory=LidarConfig)
    odometry_noise: OdometryNoiseConfig = field(default_factory=OdometryNoiseConfig)


@dataclass(frozen=True)
class RefineConfig:
    """Polygon refinement by line fitting (thesis 3.5, Algorithm 3, formulas 3.5-3.9)."""

    inlier_threshold_m: float = 0.03
    score_a: float = 1.0
    score_b: float = 4.0
    score_c: float = 0.001
    flat_angle_deg: float = 15.0  # below this, chains meet at a flat angle: no intersection
    flat_merge_distance_m: float = 0.01  # projections closer than this are averaged
    # > 0: scan points farther than this from the result are pinned (visited by the
    # polygon). Off for mapping: pinning 3-sigma noise points makes spikes that bias ICP.
    max_point_error_m: float = 0.0


@dataclass(frozen=True)
class IcpConfig:
    max_iterations: int = 30
    outlier_start_m: float = 0.5  # initial outlier threshold (thesis Table 5.3: 0.2 - 1.0)
    outlier_end_m: float = 0.03  # threshold after shrinking (3 sigma of the thesis' lidar)
    shrink: float = 0.6  # threshold multiplied by this every iteration
    tolerance_m: float = 1e-4  # converged when the update moves points less than this
    backface_culling: bool = True
    sample_spacing_m: float = 0.05  # map obstacle vectors sampled at this spacing for search
    degeneracy_ratio: float = 0.02  # eigenvalue ratio below which an axis is unconstrained
    map_radius_m: float = 32.0  # obstacle vectors farther than this from the robot are ignored
    rotation_search_rad: float = 0.35  # heading pre-alignment by wall directions (0: off)


class IcpReference(StrEnum):
    KEYFRAMES = "keyframes"  # obstacle vectors of the nearby keyframes (polyswarm.submap)
    MAP = "map"  # obstacle vectors of the merged PolyMap (the thesis' choice)


@dataclass(frozen=True)
class SubmapConfig:
    """Which keyframes a scan is matched against (polyswarm.submap)."""

    reference: str = "keyframes"  # IcpReference
    keyframes: int = 20  # at most this many keyframes nearest to the predicted pose...
    radius_m: float = 10.0  # ...within this distance of it...
    recent: int = 5  # ...plus always the latest few (the ones tracking is sure of)


@dataclass(frozen=True)
class LoopClosureConfig:
    """Loop edges and pose-graph optimisation (polyswarm.posegraph)."""

    enabled: bool = True
    min_age_keyframes: int = 30  # a loop joins keyframes at least this many keyframes apart
    radius_m: float = 5.0  # old keyframes this close to the tracked pose are matched
    keyframes: int = 10  # the old submap: at most this many keyframes
    min_inlier_fraction: float = 0.5  # of the scan's valid points, for a loop to count
    max_rmse_m: float = 0.05  # point-to-vector RMSE of an accepted loop match
    max_correction_m: float = 2.0  # a loop match moving the pose more than this is refused
    search_window_m: float = 2.0  # wide search (polyswarm.loopsearch) when ICP fails...
    search_every_keyframes: int = 5  # ...at most this often, and not right after a loop
    # the window grows with the distance driven since the last loop (drift grows with it;
    # 2-3 % on the logs' noise), up to max_search_window_m; 0: fixed
    search_window_per_m: float = 0.03
    max_search_window_m: float = 5.0
    optimise_above_m: float = 0.02  # a loop correction (heading at 2 m per rad) optimised
    tracking_sigma_m: float = 0.05  # std of a sequential edge from a successful ICP
    tracking_sigma_rad: float = 0.01
    # ... or this many times ICP's own heading std (IcpResult.heading_sigma_rad), if more:
    # that std counts scan noise only; on orebro and aces the tracking edges' heading errors
    # were a median 6 and a 90th percentile 20 times it
    heading_sigma_inflation: float = 20.0
    odometry_sigma_m: float = 0.2  # std of a sequential edge where ICP failed
    odometry_sigma_rad: float = 0.05
    loop_sigma_m: float = 0.05
    loop_sigma_rad: float = 0.01

    def search_window(self, travel_m: float) -> float:
        """The wide search's window (metres) after driving ``travel_m`` since the last loop."""
        grown = max(self.search_window_m, self.search_window_per_m * travel_m)
        return min(grown, max(self.max_search_window_m, self.search_window_m))


@dataclass(frozen=True)
class LidarMount:
    """Where the lidar sits on the robot (robot frame), and whether it is upside down."""

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0
    upside_down: bool = False  # mirrored scans: beam angles run clockwise


@dataclass(frozen=True)
class SlamConfig:
    keyframe_distance_m: float = 0.4
    keyframe_angle_rad: float = 0.3490658503988659  # 20 degrees
    frontier_range_m: float = 0.2  # dropouts (NaN, too short) become frontier points here
    # a beam with no return within the lidar's range crossed free space: it ends this far
    # out (Cartographer's missing_data_ray_length); at 0.2 m a robot turning on the spot
    # stood in the apex of unknown wedges with no room to plan (polyswarm.scan)
    no_return_free_m: float = 1.0
    # merging keyframes (polyswarm.polymap.MergeOptions)
    notch_fill_m: float = 0.01  # walls smoothed across keyframes: notches this shallow filled
    min_growth_m: float = 0.05  # new explored space thinner than this is noise along walls
    obstacle_snap_m: float = 0.05  # a frontier this close along a wall is that wall
    # a frontier lying all along beside a wall, at most this far inside it or in front of
    # it, is that wall (the chord of a grazing view of a face another view saw head-on).
    # On the maze, robots were sent to look at such faces, 2-5 cm off, and looking did not
    # close them. Inside: thinner than walls. In front: more than min_growth_m plus noise
    obstacle_snap_behind_m: float = 0.1
    obstacle_snap_front_m: float = 0.08
    # keyframe polygons are merged with their vertices on this grid, so that a robot can
    # send the polygon itself as its map delta, in whole millimetres, and the receiver
    # replays the merge bit for bit (polymap.MergeOp); 1 mm is far below lidar noise.
    # 0: not snapped, and deltas go as changed cells
    merge_quantum_m: float = 0.001
    obstacle_max_gap_m: float = 0.5  # consecutive points farther apart become a frontier...
    obstacle_gap_beams: float = 4.0  # ...unless within this many beam spacings at their range
    # rebuild_map (offline runs, after loop closures) merges this many consecutive
    # keyframes in one pass: they overlap, so a pass costs little more than one merge.
    # The maze route's 3,296 keyframes: 76 s one by one, 23 s by 8 (IoU 0.996 both, mean
    # wall distance 12.7 -> 13.5 mm, obstacle vectors 3,748 -> 4,334); 1: one by one
    rebuild_batch: int = 8
    icp: IcpConfig = field(default_factory=IcpConfig)
    submap: SubmapConfig = field(default_factory=SubmapConfig)
    loop_closure: LoopClosureConfig = field(default_factory=LoopClosureConfig)
    refine: RefineConfig = field(default_factory=RefineConfig)
    mount: LidarMount = field(default_factory=LidarMount)


@dataclass(frozen=True)
class NavConfig:
    robot_radius_m: float = 0.2
    # extra distance kept from map obstacles when planning: covers the map's wall error
    # (about 3 cm, bench slam) and leaves the local controller (which keeps the radius
    # plus ControlParams.safety_margin_m from scan points) room to follow the path
    clearance_margin_m: float = 0.1
    # distance the planned path keeps from frontier vectors (the edge of explored space),
    # 0 to robot_radius_m + clearance_margin_m. Beyond a frontier nothing is known, not a
    # wall; the local controller keeps its distance from whatever the live scan shows
    # there. With the full clearance, a door seen at an angle let no robot in (see
    # polyswarm.navgraph)
    frontier_clearance_m: float = 0.1
    # where nothing wider leads on (a door 0.7 m wide for a 0.4 m robot), the path may keep
    # only this much beyond the radius from mapped obstacles: the map's wall error. Such
    # tight passages cost navgraph.TIGHT_PENALTY_M more, so wider ways are preferred
    tight_margin_m: float = 0.03

    @property
    def obstacle_clearance_m(self) -> float:
        """Distance the planned path keeps from obstacle vectors."""
        return self.robot_radius_m + self.clearance_margin_m

    @property
    def tight_clearance_m(self) -> float:
        """... and in a tight passage."""
        return self.robot_radius_m + self.tight_margin_m


@dataclass(frozen=True)
class ExploreConfig:
    strategy: str = "hungarian"  # hungarian | greedy | nearest
    min_frontier_length_m: float = 0.4  # shorter frontier segments are not targets
    max_frontier_length_m: float = 4.0  # longer ones are split, so robots can share them
    blacklist_after_failures: int = 2
    # a robot stood at the goal and looked, yet the frontier stayed open: after this many
    # such looks it is a frontier that looking does not close (mostly wall faces seen at
    # a grazing angle); on the maze, 2 looks cost 3 robots a tenth of the mission
    blacklist_after_looks: int = 1
    no_progress_timeout_s: float = 20.0  # path cost to the target must shrink within this
    hysteresis: float = 0.8  # a new target must cost less than this times the current one
    target_separation_m: float = 3.0  # targets of different robots at least this far apart
    cycle_period_s: float = 1.0  # assignment cycle (also on events: reached, failed, joined)
    end_confirm_s: float = 3.0  # no reachable frontier for this long ends the mission
    return_home: bool = True  # robots drive back to their start when the mission ends


@dataclass(frozen=True)
class RobotEntry:
    """A robot of the swarm and its start pose in the shared map frame (x, y, theta)."""

    id: str = "r1"
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class CommsConfig:
    swarm: str = "default"
    endpoint: str = "tcp/127.0.0.1:7447"
    zenoh_config: str = ""  # optional path to a Zenoh JSON5 config file


class SensorSource(StrEnum):
    NATIVE = "native"  # polyswarm Scan and Odometry messages (the simulator, log replay)
    ROS2 = "ros2"  # sensor_msgs/LaserScan and nav_msgs/Odometry CDR (zenoh-bridge-ros2dds)


class CommandOutput(StrEnum):
    NATIVE = "native"  # polyswarm CmdVel messages (the simulator)
    TWIST = "twist"  # geometry_msgs/Twist CDR on cmd_vel_key
    GOAL = "goal"  # geometry_msgs/PoseStamped of the assigned goal on goal_key (own nav stack)
    NONE = "none"  # drive nothing (log replay, mapping only)


@dataclass(frozen=True)
class AgentIoConfig:
    """Where a robot agent reads its sensors and sends its commands.

    ``{ns}`` in a key is replaced by ``namespace`` (keys as zenoh-bridge-ros2dds exposes
    ROS 2 topics: ``/tb3_1/scan`` becomes ``tb3_1/scan``)."""

    source: str = "native"  # SensorSource
    output: str = "native"  # CommandOutput
    namespace: str = ""
    scan_key: str = "{ns}/scan"
    odom_key: str = "{ns}/odom"
    cmd_vel_key: str = "{ns}/cmd_vel"
    goal_key: str = "{ns}/goal_pose"
    map_frame: str = "map"  # frame id of goals sent to the robot's navigation stack

    def key(self, template: str) -> str:
        return template.replace("{ns}", self.namespace).strip("/")


@dataclass(frozen=True)
class PersistConfig:
    """Where agents and the coordinator keep their maps across restarts ("": nowhere)."""

    dir: str = ""


@dataclass(frozen=True)
class Config:
    map: MapConfig = field(default_factory=MapConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    slam: SlamConfig = field(default_factory=SlamConfig)
    nav: NavConfig = field(default_factory=NavConfig)
    explore: ExploreConfig = field(default_factory=ExploreConfig)
    comms: CommsConfig = field(default_factory=CommsConfig)
    agent: AgentIoConfig = field(default_factory=AgentIoConfig)
    persist: PersistConfig = field(default_factory=PersistConfig)
    robots: tuple[RobotEntry, ...] = ()  # [[robots]] tables: ids and start poses


# ---------------------------------------------------------------------------------------
# Loading, validation, saving
# ---------------------------------------------------------------------------------------


def _check_value(value: Any, hint: Any, where: str) -> Any:
    origin = typing.get_origin(hint)
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if origin in (tuple,):
        args = typing.get_args(hint)
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_check_value(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(f"{where}: expected {len(args)} values, got {len(value)}")
        return tuple(
            _check_value(v, a, f"{where}[{i}]")
            for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if origin in (types.UnionType, typing.Union):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if value is None:
            return None
        return _check_value(value, args[0], where)
    if dataclasses.is_dataclass(hint):
        return _build(hint, value, where)
    raise ConfigError(f"{where}: unsupported type {hint}")  # pragma: no cover


def _build(cls: type, data: Any, where: str) -> Any:
    if not isinstance(data, dict):
        raise ConfigError(f"{where or 'config'}: expected a table, got {data!r}")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    kwargs = {}
    for key, value in data.items():
        path = f"{where}.{key}" if where else key
        if key not in names:
            close = difflib.get_close_matches(key, names, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ConfigError(f"unknown key {path!r}{hint}")
        kwargs[key] = _check_value(value, hints[key], path)
    return cls(**kwargs)


def _merge_dicts(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge_dicts(out[k], v)
        else:
            out[k] = v
    return out


def config_to_dict(cfg: Any) -> dict:
    """The configuration as plain nested dicts (what ``save_config`` writes)."""
    out = {}
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if dataclasses.is_dataclass(v):
            out[f.name] = config_to_dict(v)
        elif isinstance(v, tuple):
            out[f.name] = [config_to_dict(x) if dataclasses.is_dataclass(x) else x for x in v]
        else:
            out[f.name] = v
    return out


def config_from_dict(data: dict, cls: type = Config) -> Any:
    """Build and validate a configuration; missing keys take their defaults."""
    cfg = _build(cls, data, "")
    validate(cfg)
    return cfg


def with_overrides(cfg: Any, overrides: dict) -> Any:
    """A copy of ``cfg`` with nested ``overrides`` applied and validated."""
    return config_from_dict(_merge_dicts(config_to_dict(cfg), overrides), type(cfg))


def load_config(path: str | Path | None, cls: type = Config) -> Any:
    """Load a TOML file (``None`` gives the defaults)."""
    if path is None:
        return cls()
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except FileNotFoundError as e:
        raise ConfigError(f"config file not found: {p}") from e
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{p}: invalid TOML: {e}") from e
    try:
        return config_from_dict(data, cls)
    except ConfigError as e:
        raise ConfigError(f"{p}: {e}") from e


def save_config(cfg: Any, path: str | Path) -> None:
    import tomli_w

    Path(path).write_text(tomli_w.dumps(config_to_dict(cfg)))


def validate(cfg: Config) -> None:
    """Range checks that types alone cannot express."""
    if not isinstance(cfg, Config):
        return
    cs = cfg.map.cell_size_m
    if not (0.1 <= cs <= 100.0) or abs(round(cs * 1000) - cs * 1000) > 1e-6:
        raise ConfigError(f"map.cell_size_m must be 0.1-100 m in whole millimetres, got {cs}")
    lid = cfg.sim.lidar
    if lid.beams < 2 or not (0 < lid.fov_rad <= 6.283185307179586):
        raise ConfigError("sim.lidar: need at least 2 beams and 0 < fov_rad <= 2 pi")
    if not (0 < lid.range_min_m < lid.range_max_m):
        raise ConfigError("sim.lidar: need 0 < range_min_m < range_max_m")
    if not (0.0 <= lid.dropout_prob < 1.0):
        raise ConfigError("sim.lidar.dropout_prob must be in [0, 1)")
    if cfg.sim.robot.radius_m <= 0:
        raise ConfigError("sim.robot.radius_m must be positive")
    for name in ("frontier_range_m", "no_return_free_m"):
        if not (0.0 < getattr(cfg.slam, name) <= 100.0):
            raise ConfigError(f"slam.{name} must be 0-100 m (not 0)")
    nav = cfg.nav
    if nav.robot_radius_m <= 0 or not (0 <= nav.tight_margin_m <= nav.clearance_margin_m):
        raise ConfigError(
            "nav: robot_radius_m must be positive and 0 <= tight_margin_m <= clearance_margin_m"
        )
    if not (0.0 <= nav.frontier_clearance_m <= nav.obstacle_clearance_m):
        raise ConfigError(
            "nav.frontier_clearance_m must be 0 to robot_radius_m + clearance_margin_m "
            f"({nav.obstacle_clearance_m:g} m), got {nav.frontier_clearance_m}"
        )
    if cfg.sim.raycast_threads < 0:
        raise ConfigError("sim.raycast_threads must be 0 (every core) or a thread count")
    for name in ("blacklist_after_failures", "blacklist_after_looks"):
        if getattr(cfg.explore, name) < 1:
            raise ConfigError(f"explore.{name} must be at least 1")
    for name in ("obstacle_snap_behind_m", "obstacle_snap_front_m"):
        if not (0.0 <= getattr(cfg.slam, name) <= 0.5):
            raise ConfigError(f"slam.{name} must be 0-0.5 m (0: off)")
    if cfg.slam.rebuild_batch < 1:
        raise ConfigError("slam.rebuild_batch must be at least 1 keyframe")
    wp = cfg.map.whole_map_precision_m
    if not (1e-5 <= wp <= 0.01 and abs(wp * 1e5 - round(wp * 1e5)) < 1e-6):
        raise ConfigError("map.whole_map_precision_m must be 0.00001-0.01 m in whole 10 um steps")
    q = cfg.slam.merge_quantum_m
    if not (q == 0 or (1e-5 <= q <= 0.05 and abs(q * 1e5 - round(q * 1e5)) < 1e-6)):
        raise ConfigError(
            "slam.merge_quantum_m must be 0 (off) or 0.00001-0.05 m in whole 10 um steps"
        )
    if cfg.explore.strategy not in ("hungarian", "greedy", "nearest"):
        raise ConfigError(
            f"explore.strategy must be hungarian, greedy or nearest, got {cfg.explore.strategy!r}"
        )
    if cfg.agent.source not in tuple(SensorSource):
        raise ConfigError(f"agent.source must be native or ros2, got {cfg.agent.source!r}")
    if cfg.agent.output not in tuple(CommandOutput):
        raise ConfigError(
            f"agent.output must be native, twist, goal or none, got {cfg.agent.output!r}"
        )
    for name in ("scan_key", "odom_key", "cmd_vel_key", "goal_key"):
        key = cfg.agent.key(getattr(cfg.agent, name))
        if not key or any(ch in key for ch in "*$?#") or "//" in key:
            raise ConfigError(f"agent.{name}: {key!r} is not a plain Zenoh key")
    ids = [r.id for r in cfg.robots]
    if len(set(ids)) != len(ids):
        raise ConfigError(f"robots: ids must be unique, got {ids}")
    for r in cfg.robots:
        if not r.id or not all(ch.isalnum() or ch in "_-" for ch in r.id) or len(r.id) > 32:
            raise ConfigError(f"robots: id {r.id!r} must be 1-32 letters, digits, '_' or '-'")
    if cfg.slam.submap.reference not in tuple(IcpReference):
        raise ConfigError(
            f"slam.submap.reference must be keyframes or map, got {cfg.slam.submap.reference!r}"
        )
    if cfg.slam.submap.keyframes < 0 or cfg.slam.submap.recent < 1:
        raise ConfigError("slam.submap: keyframes must be >= 0 and recent >= 1")
    if cfg.slam.refine.score_c <= 0:
        raise ConfigError("slam.refine.score_c must be positive (it avoids a division by zero)")
