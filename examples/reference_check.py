"""How far each step of a log's reference trajectory agrees with its own scans.

    python examples/reference_check.py csail                 # every step, suspects listed
    python examples/reference_check.py csail 364 pair.png    # one step drawn, as is and fixed

The logs' reference poses are another SLAM's output (gmapping), not ground truth. For
every pair of consecutive scans this aligns the second to the first's refined polygon
with PolySLAM's ICP, started from the reference increment, and reports how far ICP moves
from it: a few tenths of a degree is the noise of both; a step where ICP moves degrees
with most of the scan matched is a step where the reference disagrees with its scans.
``STEP PNG`` draws that pair of scans at their reference poses and at the pose ICP found.
"""

from __future__ import annotations

import dataclasses
import sys

import numpy as np

from polyswarm.config import Config
from polyswarm.data import log_paths
from polyswarm.io.carmen import read_carmen
from polyswarm.polymap import VectorType
from polyswarm.se2 import compose, relative, transform_points, wrap
from polyswarm.slam.icp import PointToVectorIcp
from polyswarm.slam.keyframe import keyframe_polygon
from polyswarm.slam.refine import refine_polygon
from polyswarm.slam.scan import scan_to_points

SUSPECT_DEG = 3.0  # ICP moved the heading this far from the reference increment...
SUSPECT_M = 0.3  # ...or the position this far...
MATCHED = 0.4  # ...with at least this share of the scan's points matched


def _points(scan, cfg) -> np.ndarray:
    p = scan_to_points(scan, cfg.slam.frontier_range_m, no_return_free_m=cfg.slam.no_return_free_m)
    return p.xy[p.valid]


def step_check(log, k: int, icp: PointToVectorIcp, cfg: Config, search: bool):
    """ICP of scan k against scan k-1's refined polygon from the reference increment."""
    c = cfg.slam
    prev = scan_to_points(
        log.scans[k - 1].scan, c.frontier_range_m, no_return_free_m=c.no_return_free_m
    )
    kf = keyframe_polygon(prev, (0.0, 0.0, 0.0), c.obstacle_max_gap_m, c.obstacle_gap_beams)
    kf, _ = refine_polygon(kf, c.refine)
    s, e, t = kf.segments()
    wall = t == VectorType.OBSTACLE
    z = relative(log.reference[k - 1], log.reference[k])
    pts = _points(log.scans[k].scan, cfg)
    if not search:
        icp = PointToVectorIcp(dataclasses.replace(icp.cfg, rotation_search_rad=0.0))
    res = icp.align(pts, z, s[wall], e[wall])
    return z, res, len(pts)


def main(name: str, step: str | None = None, png: str | None = None) -> None:
    path = next((p for p in log_paths() if p.name.startswith(name)), None)
    if path is None:
        sys.exit(f"no log named {name!r}")
    log = read_carmen(path)
    cfg = Config()
    icp = PointToVectorIcp(cfg.slam.icp)
    if step is not None:
        k = int(step)
        for search in (False, True):
            z, res, n = step_check(log, k, icp, cfg, search)
            print(
                f"step {k} ({'with' if search else 'without'} the heading search): ICP moved "
                f"{np.degrees(wrap(res.pose[2] - z[2])):+.1f} deg, "
                f"{np.hypot(*(res.pose - z)[:2]):.2f} m from the reference; "
                f"{res.inliers} of {n} points matched, converged {res.converged}"
            )
        if png:
            _draw(log, k, compose(log.reference[k - 1], res.pose), cfg, png)
        return
    rows = []
    for k in range(1, len(log.scans)):
        z, res, n = step_check(log, k, icp, cfg, search=False)
        rows.append(
            (
                k,
                np.degrees(wrap(res.pose[2] - z[2])),
                np.hypot(*(res.pose - z)[:2]),
                res.inliers / max(n, 1),
                res.converged,
            )
        )
    a = np.array(rows, dtype=float)
    ok = (a[:, 3] >= MATCHED) & (a[:, 4] > 0)
    print(
        f"{path.name}: {len(a)} steps, {int(ok.sum())} matched; ICP's heading from the "
        f"reference increment: rms {np.sqrt(np.mean(a[ok, 1] ** 2)):.2f} deg, 95th "
        f"percentile {np.percentile(np.abs(a[ok, 1]), 95):.2f} deg; position: median "
        f"{np.median(a[ok, 2]):.3f} m"
    )
    for k, dth, dxy, share, _ in a[ok & ((np.abs(a[:, 1]) > SUSPECT_DEG) | (a[:, 2] > SUSPECT_M))]:
        print(f"  suspect step {int(k)}: {dth:+.1f} deg, {dxy:.2f} m ({share:.0%} matched)")


def _draw(log, k: int, found, cfg: Config, png: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = transform_points(log.reference[k - 1], _points(log.scans[k - 1].scan, cfg))
    fig, axes = plt.subplots(1, 2, figsize=(14, 7))
    poses = (("reference poses", log.reference[k]), ("ICP", found))
    for ax, (title, pose) in zip(axes, poses, strict=True):
        b = transform_points(pose, _points(log.scans[k].scan, cfg))
        ax.plot(a[:, 0], a[:, 1], "k.", ms=3, label=f"scan {k - 1}")
        ax.plot(b[:, 0], b[:, 1], "r.", ms=3, label=f"scan {k}")
        ax.set_title(f"scan {k} at its {title}")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.axis("equal")
        ax.legend()
    fig.savefig(png, dpi=80)
    print(f"wrote {png}")


if __name__ == "__main__":
    main(*sys.argv[1:])
