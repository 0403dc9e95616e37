"""Single-robot PolySLAM runs: on a CARMEN log, or on a simulated world.

Part of the command layer (it drives the simulator). Each run yields a ``SlamRun``
with the estimated, reference and odometry trajectories, the map and timings;
``write_outputs`` writes the run folder and returns the metrics.
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

import numpy as np

from polyswarm.config import Config, config_to_dict, save_config, with_overrides
from polyswarm.errors import DataFormatError
from polyswarm.evaluation import maps as evm
from polyswarm.evaluation import trajectory as evt
from polyswarm.io.carmen import read_carmen, real_odometry
from polyswarm.io.tum import write_tum
from polyswarm.polymap import GridPolyMap, VectorType
from polyswarm.profiles import DEFAULT_PROFILE, RECORDING_SLAM
from polyswarm.se2 import compose
from polyswarm.slam.mountcheck import check_mount
from polyswarm.slam.odometry import IncrementNoise, OdometryBuffer, noisy_odometry
from polyswarm.slam.polyslam import PolySlam
from polyswarm.slam.scan import LaserScan, classify, deskew_motion

log = logging.getLogger(__name__)

Progress = Callable[[float, float], None]  # (done, total)


@dataclass
class SlamRun:
    name: str
    stamps: np.ndarray
    estimate: np.ndarray  # every scan's pose after all pose-graph corrections
    reference: np.ndarray | None  # ground truth (simulation), a log's corrected poses, None

    odometry: np.ndarray  # the noisy odometry the SLAM consumed, in the map frame
    slam: PolySlam
    keyframe_ms: list[float]
    processing_s: float  # time spent in PolySlam.process
    stream_s: float  # duration of the data stream (simulated or log time)
    simulated: bool
    info: dict = field(default_factory=dict)
    world: object | None = None  # sim.World for simulated runs
    online: np.ndarray | None = None  # every scan's pose as estimated when it came in
    final_map: GridPolyMap | None = None  # keyframes merged again at optimised poses
    stage_ms: list[dict[str, float]] = field(default_factory=list)  # per keyframe, by stage

    @property
    def map(self) -> GridPolyMap:
        return self.final_map if self.final_map is not None else self.slam.map


def finish(slam: PolySlam) -> tuple[np.ndarray, GridPolyMap | None, float]:
    """The optimised trajectory and, when loops were closed, the map merged again at the
    optimised keyframe poses; with the seconds this took (part of the processing time)."""
    t0 = time.perf_counter()
    final_map = slam.rebuild_map() if slam.loops_closed else None
    return slam.trajectory(), final_map, time.perf_counter() - t0


@dataclass(frozen=True)
class ScanIn:
    """One scan as a source (a log, a bag, a simulated world) hands it to the SLAM loop."""

    scan: LaserScan
    odom: np.ndarray  # odometry at the scan's end (what PolySLAM is given)
    odom_map: np.ndarray  # the same in the map frame (the odometry-only baseline)
    odometry_at_many: Callable | None = None  # odometry over time: the sweep is de-skewed
    truth: np.ndarray | None = None  # ground truth, where there is one
    done: float = 0.0  # progress: this much of ``total`` is done
    total: float = 0.0


@dataclass
class Trace:
    """What the SLAM loop saw and did, per scan and per keyframe."""

    stamps: list = field(default_factory=list)  # each scan's end (s)
    online: list = field(default_factory=list)  # each pose as estimated when it came in
    odometry: list = field(default_factory=list)  # ``ScanIn.odom_map``
    truth: list = field(default_factory=list)
    keyframe_ms: list = field(default_factory=list)
    stage_ms: list = field(default_factory=list)
    spent_s: float = 0.0  # in de-skewing and ``PolySlam.process``


def run_slam(slam: PolySlam, scans, progress: Progress | None = None, on_step=None) -> Trace:
    """The one SLAM loop: every ``ScanIn`` of ``scans`` through ``slam``.
    ``on_step((stamp, scan, step))`` sees every step as it is made (what a robot sends)."""
    trace = Trace()
    for item in scans:
        t0 = time.perf_counter()
        motion = None
        if item.odometry_at_many is not None:
            motion = deskew_motion(item.scan, item.odometry_at_many)
        step = slam.process(item.scan, item.odom, motion)
        trace.spent_s += time.perf_counter() - t0
        if on_step is not None:
            on_step((item.scan.end_stamp, item.scan, step))
        trace.stamps.append(item.scan.end_stamp)
        trace.online.append(step.pose)
        trace.odometry.append(item.odom_map)
        if item.truth is not None:
            trace.truth.append(item.truth)
        if step.keyframe:
            trace.keyframe_ms.append(step.timings_ms["total"])
            trace.stage_ms.append(step.timings_ms)
        if progress:
            progress(item.done, item.total)
    return trace


def _slam_run(name: str, slam: PolySlam, trace: Trace, simulated: bool, info: dict, **kw):
    """The ``SlamRun`` of a finished loop: the trajectory optimised, the map rebuilt
    (``finish``, counted in the processing time)."""
    final, final_map, rebuild_s = finish(slam)
    stamps = np.array(trace.stamps)
    stream_s = kw.pop("stream_s", float(stamps[-1] - stamps[0]) if len(stamps) > 1 else 0.0)
    return SlamRun(
        name,
        stamps,
        final,
        kw.pop("reference", np.array(trace.truth) if trace.truth else None),
        np.array(trace.odometry),
        slam,
        trace.keyframe_ms,
        trace.spent_s + rebuild_s,
        stream_s,
        simulated,
        info,
        online=np.array(trace.online),
        final_map=final_map,
        stage_ms=trace.stage_ms,
        **kw,
    )


class OdometrySource(StrEnum):
    LOG = "log"  # the robot's real wheel odometry from the log's ODOM lines
    NOISE = "noise"  # synthetic noise on the reference increments (seeded)


def run_log(
    path: str | Path,
    cfg: Config,
    noise: IncrementNoise = IncrementNoise(),
    seed: int = 0,
    progress: Progress | None = None,
    odometry: OdometrySource = OdometrySource.NOISE,
) -> SlamRun:
    """PolySLAM over a CARMEN log, on its real odometry or on synthetic noise.

    Raises DataFormatError for ``OdometrySource.LOG`` on a log without raw ODOM lines."""
    carmen = read_carmen(path)
    ref = carmen.reference
    if odometry == OdometrySource.LOG:
        odom = real_odometry(carmen)
        described = "the log's real wheel odometry (ODOM lines)"
    else:
        odom = noisy_odometry(ref, noise, seed)
        described = noise.describe()
    slam = PolySlam(cfg.slam, cfg.map.cell_size_m, initial_pose=ref[0], keep_trajectory=True)
    n = len(carmen.scans)
    scans = (
        ScanIn(s.scan, odom[k], odom[k], done=k + 1, total=n) for k, s in enumerate(carmen.scans)
    )
    trace = run_slam(slam, scans, progress)
    return _slam_run(
        Path(path).name.split(".")[0],
        slam,
        trace,
        False,
        {
            "log": str(path),
            "scans": len(carmen.scans),
            "timestamps": "synthesized (scan index x 1 s)"
            if carmen.timestamps_synthesized
            else "from the log",
            "odometry": str(odometry),
            "odometry_noise": described,
            "seed": seed,
            "reference": "the log's corrected poses (gmapping), good to a few centimetres",
        },
        reference=ref,
    )


MAX_ODOM_GAP_S = 0.5  # a scan farther than this from any odometry reading is skipped


def run_bag(
    path: str | Path,
    cfg: Config,
    progress: Progress | None = None,
    scan_topic: str | None = None,
    odom_topic: str | None = None,
    ros_distro: str = "humble",
    recording_slam: dict = RECORDING_SLAM,
    on_step=None,
) -> tuple[SlamRun, Config]:
    """PolySLAM over a recorded ROS bag (ROS 1, or rosbag2 in mcap or sqlite3; one without
    message definitions read with ``ros_distro``'s): its scans with its wheel odometry at
    each scan's time, each sweep de-skewed, every scan counted as evidence (the values of
    ``recording_slam``, ``profiles.RECORDING_SLAM``, unless the config names a robot); the lidar's
    mount from tf unless the config sets one (``protocols.tf``), checked against the lidar
    turned by pi and mirrored (``slam.mountcheck``); the driver's way of reporting no
    return read off the scans. No ground truth: the run is judged by the sharpness of its
    map against odometry alone (``evaluation.maps.occupied_cells``). Returns the run and
    the config it used. ``on_step((stamp, scan, step))`` sees every step as it is made."""
    from protocols.bags import read_bag
    from protocols.tf import choose_mount

    bag = read_bag(path, scan_topic, odom_topic, ros_distro)
    if cfg.profile == DEFAULT_PROFILE:  # a robot not named: a real lidar (profiles.py)
        cfg = with_overrides(cfg, {"slam": recording_slam})
    mount, mount_from = choose_mount(cfg.slam.mount, bag.mounts, bag.path)
    overrides = {"mount": config_to_dict(mount)}
    cfg = with_overrides(
        cfg, {"slam": overrides, "sim": {"lidar": {"out_of_range": bag.no_return}}}
    )
    odometry = OdometryBuffer(capacity=len(bag.odometry) + 1)
    for t, x, y, th in bag.odometry:
        odometry.add(t, (x, y, th))
    scans = _scans_with_odometry(bag)
    checked = check_mount(
        scans, np.array([odometry.at(s.end_stamp) for s in scans]), _mount_tuple(cfg)
    )
    if checked.better:
        log.warning("%s: %s", bag.path, checked.advice)
    start = odometry.at(scans[0].end_stamp)
    slam = PolySlam(
        cfg.slam,
        cfg.map.cell_size_m,
        initial_pose=start,
        keep_trajectory=True,
        out_of_range=cfg.sim.lidar.out_of_range,
    )
    items = (
        ScanIn(sc, pose, pose, odometry.at_many, done=k + 1, total=len(scans))
        for k, sc in enumerate(scans)
        for pose in (odometry.at(sc.end_stamp),)
    )
    trace = run_slam(slam, items, progress, on_step)
    mount_t = _mount_tuple(cfg)
    info = {
        "bag": str(path),
        "scan_topic": bag.scan_topic,
        "odom_topic": bag.odom_topic,
        "scans": len(scans),
        "skipped": dict(bag.skipped),
        "mount": mount_from,
        "mount_tf_note": bag.mounts.disagreement(),
        "mount_check": {"occupied_cells_5cm": checked.cells, "advice": checked.advice},
        "scan_topic_note": bag.scan_topic_note,
        "no_return": bag.no_return,
        "no_return_share": bag.no_return_share,
        "message_definitions": bag.definitions,
        "odometry": "the bag's wheel odometry",
        "odometry_occupied_cells_5cm": evm.occupied_cells(scans, np.array(trace.odometry), mount_t),
    }
    run = _slam_run(Path(path).name.split(".")[0], slam, trace, False, info)
    run.info["occupied_cells_5cm"] = evm.occupied_cells(scans, run.estimate, mount_t)
    return run, cfg


def _mount_tuple(cfg: Config) -> tuple[float, float, float, bool]:
    m = cfg.slam.mount
    return (m.x_m, m.y_m, m.yaw_rad, m.upside_down)


def _scans_with_odometry(bag) -> list:
    """The bag's scans within the odometry's time and with at least one valid return
    (the rest counted in ``bag.skipped``); DataFormatError when none is left."""
    t_first, t_last = bag.odometry[0, 0], bag.odometry[-1, 0]
    scans = [
        s
        for s in bag.scans
        if t_first - MAX_ODOM_GAP_S <= s.stamp and s.end_stamp <= t_last + MAX_ODOM_GAP_S
    ]
    if len(scans) < len(bag.scans):
        bag.skipped["scans outside the odometry's time"] += len(bag.scans) - len(scans)
    if not scans:
        raise DataFormatError(
            f"{bag.path}: no scan lies within the odometry's time (scans "
            f"{bag.scans[0].stamp:.1f}-{bag.scans[-1].end_stamp:.1f} s, odometry "
            f"{t_first:.1f}-{t_last:.1f} s): are they from the same recording?"
        )
    seeing = [s for s in scans if classify(s, bag.no_return)[0].any()]
    if not seeing:
        raise DataFormatError(
            f"{bag.path}: no sweep on {bag.scan_topic} holds a valid return (every beam "
            f"outside [range_min, range_max)): is it the lidar's topic?"
        )
    if len(seeing) < len(scans):
        bag.skipped["scans without a valid return"] += len(scans) - len(seeing)
    return seeing


def run_world(
    world_spec: str,
    cfg: Config,
    seed: int = 0,
    speed_mps: float = 1.0,
    progress: Progress | None = None,
    route=None,
) -> SlamRun:
    from sim import Simulation, load_world
    from sim.route import PurePursuit, coverage_route, route_length

    cfg = with_overrides(
        cfg,
        {
            "sim": {
                "seed": seed,
                "robot": {"max_linear_mps": max(speed_mps, cfg.sim.robot.max_linear_mps)},
            }
        },
    )
    world = load_world(world_spec, seed=seed)
    route = coverage_route(world) if route is None else np.asarray(route, dtype=float)
    heading = math.atan2(route[1, 1] - route[0, 1], route[1, 0] - route[0, 0])
    start = (float(route[0, 0]), float(route[0, 1]), heading)
    total = route_length(route)
    with Simulation(world, cfg.sim, 1, start_poses=[start]) as sim:
        follower = PurePursuit(route, speed=speed_mps)
        slam = PolySlam(
            cfg.slam,
            cfg.map.cell_size_m,
            initial_pose=start,
            keep_trajectory=True,
            out_of_range=cfg.sim.lidar.out_of_range,
        )
        limit_s = 3.0 * total / speed_mps + 120.0  # a stuck robot must not run forever
        scans = _route_scans(sim, follower, start, limit_s, total)
        trace = run_slam(slam, scans, progress)
        collisions = sim.robots[0].wall_collisions
        sim_s = sim.time
    info = {
        "world": world_spec,
        "route_m": total,
        "route_finished": bool(follower.done),
        "wall_contacts": collisions,
        "seed": seed,
        "speed_mps": speed_mps,
        "odometry_noise": config_to_dict(cfg.sim.odometry_noise),
    }
    return _slam_run(world.name, slam, trace, True, info, stream_s=sim_s, world=world)


def _route_scans(sim, follower, start, limit_s: float, total_m: float):
    """The simulated robot driven along a route: its scans, with odometry for the
    de-skewing, ground truth, and the route's progress (metres)."""
    odometry = OdometryBuffer()
    while not follower.done and sim.time < limit_s:
        for e in sim.step():
            odometry.add(sim.time, e.odom)  # a rolling sweep is de-skewed to its end
            yield ScanIn(
                e.scan,
                odometry.at(e.scan.end_stamp),
                compose(start, e.odom),  # in the map frame, for the baseline
                odometry.at_many,
                truth=e.true_pose,
                done=min(follower.progress, total_m),
                total=total_m,
            )
        sim.set_cmd(0, *follower.command(sim.robots[0].pose))


def stage_percentiles(stage_ms: list[dict[str, float]]) -> dict[str, dict[str, float]]:
    """{stage: {"p50": ms, "p95": ms}} over keyframes' ``SlamStep.timings_ms``."""
    names = list(stage_ms[0]) if stage_ms else []
    return {
        k: {
            "p50": float(np.median([t[k] for t in stage_ms])),
            "p95": float(np.percentile([t[k] for t in stage_ms], 95)),
        }
        for k in names
    }


def metrics(run: SlamRun) -> dict:
    kf = np.array(run.keyframe_ms) if run.keyframe_ms else np.array([math.nan])
    out = {} if run.reference is None else _trajectory_errors(run)
    out |= {
        "loops_closed": run.slam.loops_closed,
        "reseeded_keyframes": run.slam.reseeded,
        "map_rebuilt_at_optimised_poses": run.final_map is not None,
        "distance_travelled_m": float(
            evt.travelled(run.estimate if run.reference is None else run.reference)[-1]
        ),
        "vectors": int(sum(run.map.vector_counts().values())),
        "vectors_by_type": run.map.vector_counts(),
        "polygons": run.map.polygon_count(),
        "polygons_whole_map": len(run.map.dissolve()),
        "keyframes": run.slam.keyframes,
        "keyframe_p50_ms": float(np.nanmedian(kf)),
        "keyframe_p95_ms": float(np.nanpercentile(kf, 95)),
        # where a keyframe's time goes: p50 and p95 of each stage of PolySlam.process
        "keyframe_stage_ms": stage_percentiles(run.stage_ms),
        "realtime_factor": run.stream_s / run.processing_s if run.processing_s > 0 else math.inf,
        "degenerate_keyframes": run.slam.degenerate_keyframes,
        # the odometry's distance scale PolySLAM learnt (polyswarm.slam.odomscale)
        "odometry_scale": run.slam.odometry_scale.scale,
        "rejected_keyframes": run.slam.rejected_keyframes,
        **run.info,
    }
    out |= live_vs_rebuilt(run)
    out |= corrections(run)
    if run.simulated and run.world is not None:
        w = run.world
        out["map_iou"] = evm.map_iou(run.map.explored_region(), w.free)
        s, e, _ = run.map.vectors([VectorType.OBSTACLE])
        ws, we = w.wall_segments
        out["wall_distance_mean_m"] = evm.wall_distance(s, e, ws, we)
    return out


GHOST_WALL_M = 0.1  # a live wall farther than this from every rebuilt wall is a ghost


def live_vs_rebuilt(run: SlamRun) -> dict:
    """The map the robot shared as it went (``PolySlam.map``: keyframes merged at the
    poses they had then) against the same keyframes merged at the final, optimised
    poses: explored-area IoU and the share of live walls the rebuilt map lacks. Without
    loop closures the two maps are the same."""
    live = run.slam.map
    rebuilt = run.final_map if run.final_map is not None else live
    s, e, _ = live.vectors([VectorType.OBSTACLE])
    rs, re_, _ = rebuilt.vectors([VectorType.OBSTACLE])
    return {
        "live_vs_rebuilt_iou": evm.map_iou(live.explored_region(), rebuilt.explored_region()),
        "ghost_wall_share": evm.ghost_wall_share(s, e, rs, re_, GHOST_WALL_M),
    }


def corrections(run: SlamRun) -> dict:
    """Loop closures that moved keyframes' content in the live map (polyswarm.slam.follow):
    how many, the cells merged again, and the time each took (part of its keyframe's)."""
    c = run.slam.corrections
    ms = [x["ms"] for x in c]
    return {
        "corrections": len(c),
        "correction_cells": int(sum(x["cells"] for x in c)),
        "correction_p50_ms": float(np.median(ms)) if ms else None,
        "correction_p95_ms": float(np.percentile(ms, 95)) if ms else None,
    }


def _trajectory_errors(run: SlamRun) -> dict:
    est, ref = run.estimate, run.reference
    t_max, r_max = evt.max_errors(est, ref)
    dist = float(evt.travelled(ref)[-1])
    r1, r10 = evt.rpe(est, ref, 1.0), evt.rpe(est, ref, 10.0)
    return {
        "ate_rmse_m": evt.ate_rmse(est, ref),
        # the poses as they were estimated scan by scan, before later loop corrections
        "ate_rmse_online_m": evt.ate_rmse(run.online, ref) if run.online is not None else None,
        "odometry_ate_rmse_m": evt.ate_rmse(run.odometry, ref),
        "rpe_1m_trans_mean_m": r1["trans_mean_m"],
        "rpe_1m_trans_std_m": r1["trans_std_m"],
        "rpe_1m_rot_mean_deg": r1["rot_mean_deg"],
        "rpe_10m_trans_mean_m": r10["trans_mean_m"],
        "rpe_10m_trans_std_m": r10["trans_std_m"],
        "rpe_10m_rot_mean_deg": r10["rot_mean_deg"],
        "max_trans_error_m": t_max,
        "max_rot_error_deg": r_max,
        "max_trans_error_ratio": t_max / dist if dist > 0 else math.nan,
    }


def write_outputs(run: SlamRun, out: str | Path, cfg: Config) -> dict:
    from polyswarm.io.export import export_map
    from protocols.files import write_polymap

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    m = metrics(run)
    write_polymap(run.map, out / "map.polymap", cfg.map.whole_map_precision_m)
    export_map(run.map, out / "map.svg", trajectories=[run.estimate[:, :2]])
    export_map(run.map, out / "map.png", trajectories=[run.estimate[:, :2]])
    write_tum(out / "trajectory.tum", run.stamps, run.estimate)
    if run.reference is not None:
        name = "ground_truth.tum" if run.simulated else "reference.tum"
        write_tum(out / name, run.stamps, run.reference)
    write_tum(out / "odometry.tum", run.stamps, run.odometry)
    save_config(cfg, out / "config.toml")
    (out / "metrics.json").write_text(json.dumps(m, indent=2, default=float))
    return m
