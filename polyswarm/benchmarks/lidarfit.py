"""``polyswarm bench lidar``: how real low-cost lidars fail, measured on the shared
recordings, for the simulator's sensor models (``sim.lidar``).

The surfaces a beam should have met come from the recording itself: PolySLAM maps it,
and the log-odds grid of all its scans at the estimated poses (``grids.logodds``) says
where the walls are. For a sample of beams, the first occupied cell along the beam is
the surface it should have met (range ``r``; the wall's direction from the occupied
cells around it gives the incidence angle). Then, per range and incidence bin:

* the share of beams without a return;
* how invalid beams come: the lengths of their runs;
* the range noise of the returns that met that surface (median absolute deviation, as
  a standard deviation);
* mixed pixels: returns next to a jump of the true surface by more than ``JUMP_M``
  that lie between the two surfaces, not on either.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np

from polyswarm.config import Config
from polyswarm.grids.logodds import LogOddsGrid
from polyswarm.slam.scan import beam_angles, classify

SCAN_STRIDE = 3  # every third scan: consecutive sweeps see nearly the same
MATCH_M = 0.15  # a return within this of the expected surface met it
JUMP_M = 0.3  # neighbouring expected ranges this far apart: an edge between two surfaces
RANGE_BINS_M = (0.0, 1.0, 2.0, 3.0, 4.0, 6.0, 12.0)
INCIDENCE_BINS_DEG = (0.0, 30.0, 50.0, 65.0, 75.0, 90.0)
NORMAL_RADIUS_CELLS = 3  # occupied cells this close give the wall's direction


def _expected(grid: LogOddsGrid, origin, angles, rmax: float):
    """Range to the first occupied cell along each beam (inf: none) and the incidence
    angle (radians from the wall's normal) there."""
    res = grid.resolution
    occ = grid.occupied
    ts = np.arange(res / 2, rmax, res / 4)
    d = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    x = origin[0] + ts[None, :] * d[:, :1]
    y = origin[1] + ts[None, :] * d[:, 1:]
    c = np.floor((x - grid.origin[0]) / res).astype(int)
    r = np.floor((y - grid.origin[1]) / res).astype(int)
    ok = (r >= 0) & (r < occ.shape[0]) & (c >= 0) & (c < occ.shape[1])
    hit = ok & occ[np.clip(r, 0, occ.shape[0] - 1), np.clip(c, 0, occ.shape[1] - 1)]
    first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
    rng = np.where(first >= 0, ts[np.maximum(first, 0)], np.inf)
    inc = np.full(len(angles), np.nan)
    for k in np.nonzero(first >= 0)[0]:
        rr, cc = r[k, first[k]], c[k, first[k]]
        w = NORMAL_RADIUS_CELLS
        sub = occ[max(rr - w, 0) : rr + w + 1, max(cc - w, 0) : cc + w + 1]
        pts = np.argwhere(sub)
        if len(pts) < 3:
            continue
        pts = pts - pts.mean(axis=0)
        _, vec = np.linalg.eigh(pts.T @ pts)
        along = vec[:, -1]  # (row, col) direction of the wall
        wall = np.array([along[1], along[0]])
        inc[k] = math.acos(min(1.0, abs(float(wall @ d[k]))))  # beam vs wall direction
        inc[k] = math.pi / 2 - inc[k]  # from the normal
    return rng, inc


def fit(path: Path) -> dict:
    """The failure model of the lidar that recorded ``path``."""
    from polyswarm.runners.slam import run_bag
    from protocols.bags import read_bag

    run, cfg = run_bag(path, Config())
    bag = read_bag(path)
    at = set(run.stamps.tolist())
    scans = [s for s in bag.scans if s.end_stamp in at]
    m = cfg.slam.mount
    mount = (m.x_m, m.y_m, m.yaw_rad, m.upside_down)
    grid = LogOddsGrid.from_scans(scans, run.estimate, mount, bag.no_return)
    rows = []  # expected range, incidence, returned, error, at an edge, between
    runs: list[int] = []
    for s, pose in list(zip(scans, run.estimate, strict=True))[::SCAN_STRIDE]:
        valid = classify(s, bag.no_return)[0]
        a = beam_angles(s, mount) + pose[2]
        c, sn = math.cos(pose[2]), math.sin(pose[2])
        origin = (pose[0] + c * m.x_m - sn * m.y_m, pose[1] + sn * m.x_m + c * m.y_m)
        exp, inc = _expected(grid, origin, a, s.range_max)
        r = np.asarray(s.ranges, dtype=float)
        jump = np.abs(np.diff(np.where(np.isfinite(exp), exp, s.range_max)))
        edge = np.zeros(len(r), dtype=bool)
        edge[:-1] |= jump > JUMP_M
        edge[1:] |= jump > JUMP_M
        near = np.minimum(np.roll(exp, 1), np.roll(exp, -1))
        far = np.maximum(np.roll(exp, 1), np.roll(exp, -1))
        between = (
            valid
            & edge
            & (r > np.minimum(near, exp) + MATCH_M / 3)
            & (r < np.maximum(far, exp) - MATCH_M / 3)
        )
        seen = np.isfinite(exp)
        rows.append(
            np.stack(
                [exp, inc, valid & (np.abs(r - exp) < MATCH_M), r - exp, edge, between, seen],
                axis=1,
            )
        )
        bad = ~valid
        edges = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
        runs += (np.nonzero(edges == -1)[0] - np.nonzero(edges == 1)[0]).tolist()
    t = np.concatenate(rows)
    exp, inc, met, err, edge, between, seen = t.T
    seen = seen.astype(bool)
    met = met.astype(bool)
    out: dict = {"beams": int(seen.sum()), "no_return_share": bag.no_return_share}
    out["drop_by_range"] = _binned(exp[seen], ~met[seen], RANGE_BINS_M)
    ok = seen & np.isfinite(inc)
    out["drop_by_incidence_deg"] = _binned(np.degrees(inc[ok]), ~met[ok], INCIDENCE_BINS_DEG)
    sigma = [
        1.4826 * float(np.median(np.abs(err[met & (exp >= lo) & (exp < hi)])))
        if (met & (exp >= lo) & (exp < hi)).sum() >= 30
        else None
        for lo, hi in itertools.pairwise(RANGE_BINS_M)
    ]
    out["noise_sigma_by_range_m"] = {
        f"{lo:g}-{hi:g}": s for (lo, hi), s in zip(_pairs(RANGE_BINS_M), sigma, strict=True)
    }
    edge_returns = (edge.astype(bool) & ~np.isnan(err)) & seen
    out["mixed_pixel_share_at_edges"] = (
        float(between[edge_returns].mean()) if edge_returns.any() else None
    )
    rl = np.array(runs)
    out["invalid_run_beams"] = {
        "median": float(np.median(rl)) if len(rl) else 0.0,
        "share_in_runs_over_10": float(rl[rl > 10].sum() / max(rl.sum(), 1)),
    }
    return out


def _pairs(bins):
    return list(itertools.pairwise(bins))


def _binned(x: np.ndarray, flag: np.ndarray, bins) -> dict:
    out = {}
    for lo, hi in _pairs(bins):
        sel = (x >= lo) & (x < hi)
        out[f"{lo:g}-{hi:g}"] = (
            {"share": float(flag[sel].mean()), "beams": int(sel.sum())} if sel.sum() >= 30 else None
        )
    return out


def run(bags: Path) -> dict:
    from polyswarm.benchmarks.maps import RECORDINGS

    return {
        name: {"lidar": what, **fit(bags / f"{name}.bag")}
        for name, what in RECORDINGS.items()
        if "real" in what
    }


def simulated(profile: str, world_spec: str = "office", poses: int = 60, seed: int = 0) -> dict:
    """How the simulator's model of ``profile``'s lidar fails in a world: scans from
    ``poses`` random free poses (seeded), the share of beams without a return (beyond the
    range included, as in a recording) and the runs of invalid beams."""
    from polyswarm.config import with_overrides
    from polyswarm.slam.scan import classify
    from sim import Simulation, load_world

    cfg = with_overrides(Config(), {"profile": profile, "sim": {"seed": seed}})
    world = load_world(world_spec, seed=seed)
    rng = np.random.default_rng(seed)
    inner = world.free.buffer(-0.5)
    x0, y0, x1, y1 = inner.bounds
    shares, runs = [], []
    with Simulation(world, cfg.sim, 1, start_poses=[(*world.start, 0.0)]) as sim:
        import shapely

        for _ in range(poses):
            while True:
                x, y = rng.uniform(x0, x1), rng.uniform(y0, y1)
                if shapely.intersects_xy(inner, x, y):
                    break
            sim.robots[0].pose = np.array([x, y, rng.uniform(-np.pi, np.pi)])
            sim._prev[0] = sim.robots[0].pose.copy()
            scan = sim.scan()[0].scan
            valid = classify(scan, cfg.sim.lidar.out_of_range)[0]
            shares.append(1.0 - valid.mean())
            edges = np.diff(np.concatenate([[0], (~valid).astype(np.int8), [0]]))
            runs += (np.nonzero(edges == -1)[0] - np.nonzero(edges == 1)[0]).tolist()
    return {
        "no_return_share": float(np.mean(shares)),
        "invalid_run_beams_median": float(np.median(runs)) if runs else 0.0,
    }
