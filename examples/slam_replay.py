"""PolySLAM on recorded scans: where a run's processor time goes, and old code against new.

    python examples/slam_replay.py record data:maze maze.npz          # once (maze: 100 s)
    python examples/slam_replay.py replay maze.npz [SCANS] [BATCHES]  # e.g. 8000 1,8
    python examples/slam_replay.py refine maze.npz

``record`` drives the simulated robot along the world's coverage route at 1 m/s, as
``polyswarm slam --world`` does, and saves every scan, odometry reading and true pose.
``replay`` feeds the first SCANS scans (default all) to ``PolySlam.process`` and prints
the keyframe stage p50 / p95 (ms), the processing time, the maximum error against the
truth, and for each rebuild batch (``slam.rebuild_batch``, default the config's) the
time ``rebuild_map`` takes and its map (IoU, mean wall distance, obstacle vectors).
``refine`` refines the keyframe polygons of every tenth of the first 6,000 scans at the
true pose and prints p50 / p95 (ms) and a digest of the refined rings.

``POLYSWARM_CODE=/other/checkout`` imports polyswarm from another checkout (for example
``git worktree add /tmp/old COMMIT``): run both at once to compare old and new code on
the same scans (a plain PYTHONPATH does not override this venv's editable install).
"""

from __future__ import annotations

import os
import sys

if os.environ.get("POLYSWARM_CODE"):
    sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in repr(f)]
    sys.path.insert(0, os.environ["POLYSWARM_CODE"])

import dataclasses
import hashlib
import math
import time

import numpy as np

import polyswarm
from polyswarm.config import Config
from polyswarm.evaluation import maps as evm
from polyswarm.polymap import VectorType
from polyswarm.slam.scan import LaserScan


def record(world_name: str, out: str) -> None:
    from sim import Simulation, load_world
    from sim.route import PurePursuit, coverage_route

    cfg = Config()
    world = load_world(world_name, seed=0)
    route = coverage_route(world)
    start = (*route[0], math.atan2(*(route[1] - route[0])[::-1]))
    ranges, odom, stamps, truth = [], [], [], []
    with Simulation(world, cfg.sim, 1, start_poses=[start]) as sim:
        follower = PurePursuit(route, speed=1.0)
        while not follower.done and sim.time < 10_000:
            for e in sim.step():
                ranges.append(e.scan.ranges.astype(np.float32))
                odom.append(e.odom)
                stamps.append(e.scan.stamp)
                truth.append(e.true_pose)
                scan = e.scan
            sim.set_cmd(0, *follower.command(sim.robots[0].pose))
    meta = [scan.angle_min, scan.angle_increment, scan.range_min, scan.range_max]
    np.savez_compressed(
        out,
        ranges=np.array(ranges),
        odom=np.array(odom),
        stamps=np.array(stamps),
        truth=np.array(truth),
        start=np.array(start),
        meta=np.array(meta),
        world=world_name,
    )
    print(f"{len(ranges)} scans, {stamps[-1] - stamps[0]:.0f} s")


def _scans(d: dict, n: int):
    am, ai, rmin, rmax = d["meta"]
    for k in range(n):
        yield k, LaserScan(d["ranges"][k].astype(float), am, ai, rmin, rmax, float(d["stamps"][k]))


def replay(path: str, scans: int, batches: list[int] | None) -> None:
    from polyswarm.slam.polyslam import PolySlam
    from sim import load_world

    d = dict(np.load(path))  # loaded once: an npz re-reads an array at every access
    n = min(scans, len(d["ranges"]))
    cfg = Config()
    slam = PolySlam(cfg.slam, cfg.map.cell_size_m, initial_pose=d["start"], keep_trajectory=True)
    stages, spent = [], 0.0
    for k, scan in _scans(d, n):
        t0 = time.perf_counter()
        step = slam.process(scan, d["odom"][k])
        spent += time.perf_counter() - t0
        if step.keyframe:
            stages.append(step.timings_ms)
    err = np.hypot(*(slam.trajectory()[:, :2] - d["truth"][:n, :2]).T)
    print(f"{polyswarm.__file__}: {len(stages)} keyframes, {slam.loops_closed} loops")
    for name in stages[0]:
        v = [s[name] for s in stages]
        print(f"  {name:8s} p50 {np.median(v):7.2f}  p95 {np.percentile(v, 95):7.2f} ms")
    stream_s = float(d["stamps"][n - 1] - d["stamps"][0])
    print(f"  processing {spent:.1f} s for {stream_s:.0f} s of scans, max error {err.max():.4f} m")
    world = load_world(str(d["world"]))
    ws, we = world.wall_segments
    # (code older than slam.rebuild_batch rebuilds one by one: shown as batch 1)
    for b in batches or [getattr(cfg.slam, "rebuild_batch", 1)]:
        if hasattr(cfg.slam, "rebuild_batch"):
            slam.cfg = dataclasses.replace(cfg.slam, rebuild_batch=b)
        t0 = time.perf_counter()
        pmap = slam.rebuild_map()
        dt = time.perf_counter() - t0
        s, e, _ = pmap.vectors([VectorType.OBSTACLE])
        print(
            f"  rebuild by {b}: {dt:.1f} s, real-time factor {stream_s / (spent + dt):.2f}, "
            f"IoU {evm.map_iou(pmap.explored_region(), world.free):.4f}, wall distance "
            f"{1e3 * evm.wall_distance(s, e, ws, we):.1f} mm, obstacle vectors {len(s)}, "
            f"polygons {pmap.polygon_count()}"
        )


def refine(path: str) -> None:
    from polyswarm.slam.keyframe import keyframe_polygon
    from polyswarm.slam.refine import refine_polygon
    from polyswarm.slam.scan import scan_to_points

    d = dict(np.load(path))
    c = Config().slam
    polys = [
        keyframe_polygon(
            scan_to_points(scan, c.frontier_range_m, no_return_free_m=c.no_return_free_m),
            d["truth"][k],
            c.obstacle_max_gap_m,
            c.obstacle_gap_beams,
        )
        for k, scan in _scans(d, min(6000, len(d["ranges"])))
        if k % 10 == 0
    ]
    ms, digest = [], hashlib.sha256()
    for p in polys:
        t0 = time.perf_counter()
        out, how = refine_polygon(p, c.refine)
        ms.append(1e3 * (time.perf_counter() - t0))
        digest.update(out.shell.xy.tobytes() + out.shell.types.tobytes() + how.encode())
    print(
        f"{polyswarm.__file__}: {len(polys)} keyframes, refinement p50 {np.median(ms):.2f} "
        f"p95 {np.percentile(ms, 95):.2f} ms, output digest {digest.hexdigest()[:16]}"
    )


if __name__ == "__main__":
    what, args = sys.argv[1], sys.argv[2:]
    if what == "record":
        record(args[0], args[1])
    elif what == "replay":
        n = int(args[1]) if len(args) > 1 else 10**9
        replay(args[0], n, [int(b) for b in args[2].split(",")] if len(args) > 2 else None)
    elif what == "refine":
        refine(args[0])
    else:
        sys.exit(__doc__)
