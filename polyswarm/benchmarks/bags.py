"""``polyswarm bench bags``: recorded ROS bags through PolySLAM and through an agent.

Bags: the shared TurtleBot3 bag (``../shared/data/bags``: ROS 1, 457 scans at 5 Hz, no
tf) and a rosbag2 (mcap) of ``GENERATED_SCANS`` scans written by
``polyswarm.benchmarks.bagmaker`` (a lidar mounted upside down, said by /tf_static).
For each:

* ``polyswarm slam BAG`` as a user runs it: ``realtime_factor`` is the bag's duration
  over the wall time of the whole run (reading the bag, SLAM, the final map), and the
  map's sharpness against odometry alone (occupied 5 cm cells, fewer is sharper);
* ``mount``: where the lidar's mount came from, and for the generated bag its error
  against the mount the bag was made with;
* ``polyswarm agent --replay BAG --rate REPLAY_RATE``: the bag as ROS 2 CDR over Zenoh on
  loopback into an agent process; scans it processed and messages it refused.
"""

from __future__ import annotations

import math
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

GENERATED_SCANS = 600  # 60 s at 10 Hz: the "bag of 500+ scans"
REPLAY_RATE = 5.0


def replay(bag: Path, rate: float = REPLAY_RATE) -> dict:
    """``polyswarm agent --replay`` in its own process; its summary line parsed."""
    cmd = [sys.executable, "-m", "polyswarm", "agent", "--id", "r1", "--replay", str(bag)]
    from polyswarm.runners.children import free_port

    cmd += ["--rate", str(rate), "--listen", f"tcp/127.0.0.1:{free_port()}"]
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=1200, check=False)
    wall = time.perf_counter() - t0
    m = re.search(r"r1: (\d+) scans, (\d+) keyframes.* (\d+) messages refused", res.stderr)
    if res.returncode != 0 or m is None:
        raise RuntimeError(f"agent replay of {bag} failed: {res.stderr[-2000:]}")
    return {
        "scans": int(m.group(1)),
        "keyframes": int(m.group(2)),
        "refused": int(m.group(3)),
        "wall_s": wall,
        "rate": rate,
    }


def slam(bag: Path, truth_mount=None) -> dict:
    from polyswarm.config import Config
    from polyswarm.runners.slam import metrics, run_bag

    t0 = time.perf_counter()
    run, cfg = run_bag(bag, Config())
    m = metrics(run)
    wall = time.perf_counter() - t0
    out = {
        "scans": m["scans"],
        "duration_s": run.stream_s,
        "wall_s": wall,
        "realtime_factor": run.stream_s / wall,
        "occupied_cells_5cm": m["occupied_cells_5cm"],
        "odometry_occupied_cells_5cm": m["odometry_occupied_cells_5cm"],
        "sharper_than_odometry": m["occupied_cells_5cm"] <= m["odometry_occupied_cells_5cm"],
        "loops_closed": m["loops_closed"],
        "keyframe_p95_ms": m["keyframe_p95_ms"],
        "skipped": m["skipped"],
        "mount": m["mount"],
    }
    if truth_mount is not None:
        got = cfg.slam.mount
        out["mount_error_m"] = math.hypot(got.x_m - truth_mount[0], got.y_m - truth_mount[1])
        out["mount_error_rad"] = abs(math.remainder(got.yaw_rad - truth_mount[2], 2 * math.pi))
        out["mount_upside_down_matches"] = got.upside_down == truth_mount[3]
    return out


def run(shared_bag: Path | None) -> dict:
    from polyswarm.benchmarks.bagmaker import MOUNT, make_bag

    results = {}
    with tempfile.TemporaryDirectory() as d:
        generated = make_bag(Path(d) / "room", "mcap", n_scans=GENERATED_SCANS)
        bags = {"generated-mcap": (generated, MOUNT)}
        if shared_bag is not None:
            bags[shared_bag.stem] = (shared_bag, None)
        for name, (path, mount) in bags.items():
            results[name] = {"slam": slam(path, mount), "replay": replay(path)}
    return {
        "bags": results,
        "realtime_factor_min": min(r["slam"]["realtime_factor"] for r in results.values()),
        "refused_total": sum(r["replay"]["refused"] for r in results.values()),
    }
