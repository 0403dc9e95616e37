"""``polyswarm bench slam``: the thesis' experiments, measured.

* simulated thesis worlds (Table 5.1): max translational error over distance, map IoU
* real logs (Radish, corrected poses as reference): ATE against odometry alone
* refinement on a ``curves`` keyframe (Table 5.4): vectors and the farthest scan point
* map size against the thesis' polygon counts (Table 5.8); keyframe time, real-time factor
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import shapely

from polyswarm.config import Config, RefineConfig, with_overrides
from polyswarm.data import WORLDS, log_paths
from polyswarm.errors import DataFormatError
from polyswarm.runners.slam import OdometrySource, metrics, run_log, run_world, stage_percentiles
from polyswarm.slam.odometry import IncrementNoise
from polyswarm.slam.refine import refine_polygon

THESIS_MAX_ERROR_RATIO = {"loop": 0.0043, "cross": 0.0016, "zigzag": 0.00074, "maze": 0.00062}
THESIS_POLYGONS = {"loop": 209585, "cross": 429876, "zigzag": 469110}  # Table 5.8, no overlay


def _curves_keyframe(seed: int):
    from polyswarm.raycast import cast_rays
    from polyswarm.slam.keyframe import keyframe_polygon
    from polyswarm.slam.scan import LaserScan, scan_to_points
    from sim.world import load_world

    world = load_world("curves")
    s, e = world.wall_segments
    rng = np.random.default_rng(seed)
    pose = (3.5, 3.0, 0.3)
    fov, n = math.radians(350), 1401  # thesis 5.6: 350 degrees at 0.25 degree steps
    a = np.linspace(-fov / 2, fov / 2, n)
    r = cast_rays(pose[:2], a + pose[2], s, e, 30.0) + rng.normal(0, 0.01, n)
    pts = scan_to_points(LaserScan(r, -fov / 2, a[1] - a[0], 0.05, 30.0))
    return keyframe_polygon(pts, pose, 0.5)


def refinement(seeds=(0, 1, 2, 3, 4)) -> dict:
    out = {}
    configs = {
        "thesis_defaults": RefineConfig(),
        "bounded_0.03": RefineConfig(inlier_threshold_m=0.025, max_point_error_m=0.03),
    }
    for name, cfg in configs.items():
        vec, far = [], []
        for seed in seeds:
            kf = _curves_keyframe(seed)
            ref, _ = refine_polygon(kf, cfg)
            d = shapely.distance(shapely.LinearRing(ref.shell.xy), shapely.points(kf.shell.xy))
            vec.append(len(ref.shell))
            far.append(float(d.max()))
        out[name] = {
            "raw_vectors": len(kf.shell),
            "vectors_max": int(max(vec)),
            "vectors_median": float(np.median(vec)),
            "farthest_point_m_max": float(max(far)),
        }
    return out


# what a run's map following the pose graph did, beside the keyframe time of the same run
FOLLOWING_KEYS = (
    "live_vs_rebuilt_iou",
    "ghost_wall_share",
    "keyframe_p95_ms",
    "corrections",
    "correction_cells",
    "correction_p50_ms",
    "correction_p95_ms",
)


def _growing(path, cfg: Config, **kw) -> dict:
    """The same run with a map that only grows (``slam.map_follows_graph`` off): the
    figures before maps followed the pose graph."""
    g = metrics(run_log(path, with_overrides(cfg, {"slam": {"map_follows_graph": False}}), **kw))
    keys = ("ate_rmse_m", "live_vs_rebuilt_iou", "ghost_wall_share", "keyframe_p95_ms")
    return {k: g[k] for k in keys}


def _real_odometry(path, cfg: Config, progress) -> dict:
    """The same log on the robot's real wheel odometry (its ODOM lines), where it has
    them (orebro has none: None)."""
    if progress:
        progress(f"log {path.name}, real odometry")
    try:
        m = metrics(run_log(path, cfg, odometry=OdometrySource.LOG))
    except DataFormatError:
        return {"real_odometry": None}
    if progress:
        progress(f"log {path.name}, real odometry, a map that only grows")
    return {
        "real_odometry": {
            "ate_rmse_m": m["ate_rmse_m"],
            "odometry_ate_rmse_m": m["odometry_ate_rmse_m"],
            "ate_rmse_online_m": m["ate_rmse_online_m"],
            "loops_closed": m["loops_closed"],
            "reseeded_keyframes": m["reseeded_keyframes"],
            "realtime_factor": m["realtime_factor"],
            **{k: m[k] for k in FOLLOWING_KEYS},
            "growing": _growing(path, cfg, odometry=OdometrySource.LOG),
        }
    }


def run(progress: Callable[[str], None] | None = None, worlds=WORLDS, log_seeds: int = 1) -> dict:
    """``log_seeds``: odometry-noise seeds 0..n-1 per log (the headline figures are seed
    0's; the others show how much one draw of the noise matters)."""
    cfg = Config()
    res: dict = {"worlds": {}, "logs": {}}
    kf_ms, rt, stages = [], [], []
    for w in worlds:
        if progress:
            progress(f"simulated {w}")
        r = run_world(f"data:{w}", cfg, seed=0)
        m = metrics(r)
        kf_ms += r.keyframe_ms
        stages += r.stage_ms
        rt.append(m["realtime_factor"])
        res["worlds"][w] = {
            "distance_travelled_m": m["distance_travelled_m"],
            "max_trans_error_m": m["max_trans_error_m"],
            "max_rot_error_deg": m["max_rot_error_deg"],
            "max_trans_error_ratio": m["max_trans_error_ratio"],
            "thesis_max_trans_error_ratio": THESIS_MAX_ERROR_RATIO[w],
            "ate_rmse_m": m["ate_rmse_m"],
            "odometry_ate_rmse_m": m["odometry_ate_rmse_m"],
            "map_iou": m["map_iou"],
            "wall_distance_mean_m": m["wall_distance_mean_m"],
            "polygons": m["polygons"],
            "vectors": m["vectors"],
            "thesis_polygons": THESIS_POLYGONS.get(w),
            "route_finished": m["route_finished"],
            "realtime_factor": m["realtime_factor"],
            "loops_closed": m["loops_closed"],
            **{k: m[k] for k in FOLLOWING_KEYS},
        }
    world_kf_ms = list(kf_ms)  # 720-beam scans, the speed target's
    for p in log_paths():
        if progress:
            progress(f"log {p.name}")
        r = run_log(p, cfg, IncrementNoise(), seed=0)
        m = metrics(r)
        kf_ms += r.keyframe_ms
        by_seed = [m["ate_rmse_m"]]
        for seed in range(1, log_seeds):
            if progress:
                progress(f"log {p.name}, noise seed {seed}")
            by_seed.append(metrics(run_log(p, cfg, IncrementNoise(), seed=seed))["ate_rmse_m"])
        res["logs"][p.name.split("-corrected")[0]] = {
            "ate_rmse_m_by_seed": by_seed,
            "ate_rmse_median_m": float(np.median(by_seed)),
            "ate_rmse_max_m": float(max(by_seed)),
            "ate_rmse_m": m["ate_rmse_m"],
            "odometry_ate_rmse_m": m["odometry_ate_rmse_m"],
            "improvement": m["odometry_ate_rmse_m"] / m["ate_rmse_m"],
            "ate_rmse_online_m": m["ate_rmse_online_m"],  # before later loop corrections
            "loops_closed": m["loops_closed"],
            "rpe_1m_trans_mean_m": m["rpe_1m_trans_mean_m"],
            "max_trans_error_m": m["max_trans_error_m"],
            "distance_travelled_m": m["distance_travelled_m"],
            **{k: m[k] for k in FOLLOWING_KEYS},
            "growing": _growing(p, cfg, noise=IncrementNoise(), seed=0),
        }
        res["logs"][p.name.split("-corrected")[0]].update(_real_odometry(p, cfg, progress))
    if progress:
        progress("refinement")
    res["refinement_curves"] = refinement()
    res["keyframe_p50_ms"] = float(np.median(kf_ms))
    res["keyframe_p95_ms"] = float(np.percentile(kf_ms, 95))
    if world_kf_ms:
        res["keyframe_p95_ms_720_beams"] = float(np.percentile(world_kf_ms, 95))
        res["keyframe_stage_ms_720_beams"] = stage_percentiles(stages)
    res["realtime_factor_min"] = float(min(rt)) if rt else math.nan
    return res
