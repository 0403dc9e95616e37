"""``polyswarm bench maps``: are the maps right?

* every shared recording (``../shared/data/bags``): the PolyMap ``polyswarm slam`` builds
  against the log-odds grid of the same scans at the same poses (``grids.logodds``, what
  a grid SLAM package builds at its usual settings): wall recall, walls typed frontier,
  explored area where no beam went, explored over the grid's free area
  (``evaluation.grid_scores``). Side by side: the same run with keyframe polygons of one
  sweep each (``slam.evidence`` off), as PolySLAM mapped before;
* every simulated world and robot profile: PolySLAM driven along a route through the
  world, its map against the ground truth: IoU with the true free space its lidar could
  see from the true poses (``seen_space``), ghost walls (obstacle vectors farther than
  ``GHOST_M`` from every true wall, share of their length) and explored area beyond the
  walls (outside the true free space, share of the explored area).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import shapely

from polyswarm.config import Config, with_overrides
from polyswarm.evaluation.grid_scores import score_against_grid
from polyswarm.evaluation.maps import map_iou, phantom_obstacles
from polyswarm.grids.logodds import LogOddsGrid
from polyswarm.polymap import VectorType
from polyswarm.profiles import RECORDING_SLAM

GHOST_M = 0.1  # an obstacle vector this far from every true wall is a ghost wall
# the shared recordings, and what made them (only real lidars count for the targets)
RECORDINGS = {
    "neato-office-1": "real Neato XV-11-class lidar",
    "neato-square": "real Neato XV-11-class lidar",
    "pioneer-hokuyo-corridor": "real Hokuyo URG-04LX",
    "turtlebot3-gazebo": "simulated LDS-01 (Gazebo)",
}
WORLDS = ("office", "rooms", "furnished", "data:nav2-depot", "data:nav2-warehouse")
SCORES = ("wall_recall", "walls_as_frontier", "explored_unseen_share", "explored_over_free")


def recording(path: Path, evidence: bool = True) -> dict:
    """``polyswarm slam`` on one bag, scored against its log-odds grid."""
    from polyswarm.runners.slam import run_bag
    from protocols.bags import read_bag

    # off: keyframes of one sweep each, as before, with the recording's other values
    values = {**RECORDING_SLAM, "evidence": {"enabled": evidence}}
    run, used = run_bag(path, Config(), recording_slam=values)
    bag = read_bag(path)
    at = set(run.stamps.tolist())
    scans = [s for s in bag.scans if s.end_stamp in at]
    m = used.slam.mount
    grid = LogOddsGrid.from_scans(
        scans, run.estimate, (m.x_m, m.y_m, m.yaw_rad, m.upside_down), bag.no_return
    )
    out = score_against_grid(run.map, grid)
    out["scans"] = len(scans)
    out["keyframe_p95_ms"] = float(np.percentile(run.keyframe_ms, 95))
    out["no_return_share"] = bag.no_return_share
    return out


def world(spec: str, profile: str, seed: int = 0) -> dict:
    """PolySLAM along a route through a simulated world, its map against the truth."""
    from polyswarm.runners.slam import run_world

    cfg = with_overrides(Config(), {"profile": profile})
    speed = cfg.sim.robot.max_linear_mps
    run = run_world(spec, cfg, seed, speed)
    w = run.world
    explored = run.map.explored_region()
    seen = seen_space(w, run.reference, cfg.sim.lidar)
    s, e, _ = run.map.vectors([VectorType.OBSTACLE])
    ws, we = w.wall_segments
    length = float(np.hypot(*(e - s).T).sum()) if len(s) else 0.0
    beyond = shapely.difference(explored, w.free, grid_size=1e-6).area
    return {
        "map_iou": map_iou(explored, seen),
        "seen_m2": float(seen.area),
        "ghost_walls": phantom_obstacles(s, e, ws, we, GHOST_M) / length if length else 0.0,
        "explored_beyond_walls": float(beyond / explored.area) if explored.area else 0.0,
        "keyframes": run.slam.keyframes,
        "keyframe_p95_ms": float(np.percentile(run.keyframe_ms, 95)),
    }


SEEN_EVERY_M = 0.25  # the true space the lidar saw: from poses this far apart ...
SEEN_RAYS = 720  # ... with this many rays over its field of view


def seen_space(world, true_poses: np.ndarray, lidar) -> shapely.Geometry:
    """The true free space the route's lidar could see: rays cast against the true walls
    from the true poses, up to the lidar's range, within its field of view."""
    from polyswarm.evaluation.trajectory import travelled
    from polyswarm.raycast import cast_rays

    s, e = world.wall_segments
    d = travelled(true_poses)
    pick = np.unique(np.searchsorted(d, np.arange(0.0, d[-1] + SEEN_EVERY_M, SEEN_EVERY_M)))
    pick = pick[pick < len(true_poses)]
    half = lidar.fov_rad / 2
    a = np.linspace(-half, half, SEEN_RAYS, endpoint=lidar.fov_rad < 2 * np.pi - 1e-6)
    stars = []
    for x, y, th in true_poses[pick]:
        r = np.minimum(cast_rays((x, y), a + th, s, e, lidar.range_max_m), lidar.range_max_m)
        pts = np.stack([x + r * np.cos(a + th), y + r * np.sin(a + th)], axis=1)
        if lidar.fov_rad < 2 * np.pi - 1e-6:
            pts = np.vstack([[x, y], pts])
        stars.append(shapely.Polygon(pts).buffer(0))
    return shapely.intersection(shapely.union_all(stars), world.free, grid_size=1e-6)


def run(
    bags: Path | None,
    worlds=WORLDS,
    profiles=("thesis", "turtlebot3", "turtlebot4", "hokuyo"),
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
) -> dict:
    out: dict = {"recordings": {}, "worlds": {}}
    for name, what in RECORDINGS.items() if bags is not None else ():
        path = bags / f"{name}.bag"
        if progress:
            progress(f"recording {name}")
        out["recordings"][name] = {
            "lidar": what,
            "evidence": recording(path, True),
            "keyframes_alone": recording(path, False),
        }
    for spec in worlds:
        for profile in profiles:
            if progress:
                progress(f"{spec}, {profile}")
            out["worlds"].setdefault(spec, {})[profile] = world(spec, profile, seed)
    real = [r["evidence"] for n, r in out["recordings"].items() if "real" in r["lidar"]]
    if real:
        out["real_worst"] = {
            "wall_recall": min(r["wall_recall"] for r in real),
            "walls_as_frontier": max(r["walls_as_frontier"] for r in real),
            "explored_unseen_share": max(r["explored_unseen_share"] for r in real),
            "explored_over_free_min": min(r["explored_over_free"] for r in real),
            "explored_over_free_max": max(r["explored_over_free"] for r in real),
        }
    sims = [r for w in out["worlds"].values() for r in w.values()]
    if sims:
        out["worlds_worst"] = {
            "map_iou": min(r["map_iou"] for r in sims),
            "ghost_walls": max(r["ghost_walls"] for r in sims),
            "explored_beyond_walls": max(r["explored_beyond_walls"] for r in sims),
        }
    return out
