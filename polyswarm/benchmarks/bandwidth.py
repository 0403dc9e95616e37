"""``polyswarm bench bandwidth``: PolyMap deltas against occupancy-grid map sharing.

The same noisy scans and SLAM poses go into PolySLAM and into a 5 cm grid built as
gmapping builds it (``polyswarm.grids.counting``, ray casting; never ground truth). At every
keyframe, where PolySLAM emits a map delta, each scheme's message for that update is
measured:

* ``polymap_delta`` / ``polymap_delta_zlib``: what the robot agent sends for the change:
  the keyframe's merge (``polymap-merge``, replayed by the receiver) when it is smaller
  than the changed cells, else the cells (``polymap-delta``);
* ``polymap_cells``: the changed cells alone, as sent before merges were (for comparison);
* ``grid_full`` / ``_zlib`` / ``_png``: the whole nav_msgs/OccupancyGrid (CDR);
* ``grid_update`` / ``_zlib`` / ``_png``: a map_msgs/OccupancyGridUpdate of the bounding
  box of the cells whose value changed (CDR);
* ``keyframe_scans``: the keyframe's scan itself with its pose, as a collaborative SLAM
  system shares keyframes (the receiver builds the map): ranges on a 1 cm grid, each as
  the difference to the previous beam's, zlib'd (``encode_keyframe_scan``).

PolyMap is compared with the best of all the baselines (``best_baseline``) and, as
before, with the best grid scheme.

The grid's extent is fixed up front to the final map's bounds, so grid updates never
need a full resend when the map grows: the baseline's best case. PNG sizes are of the
cells only (no message header), also in the baseline's favour.
Runs: every CARMEN log of ``../shared/data/logs`` and a simulated exploration.
"""

from __future__ import annotations

import csv
import io
import math
import struct
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from polyswarm.config import Config
from polyswarm.errors import DeltaGapError
from polyswarm.grids.counting import CountingGrid
from polyswarm.polymap import GridPolyMap, MapDelta, MergeOp, cells_digest
from polyswarm.slam.follow import Atlas, CorrectionOp, replay_correction
from polyswarm.slam.scan import LaserScan

SCHEMES = (
    "polymap_delta",
    "polymap_delta_zlib",
    "polymap_cells",
    "grid_full",
    "grid_full_zlib",
    "grid_full_png",
    "grid_update",
    "grid_update_zlib",
    "grid_update_png",
    "keyframe_scans",
)
GRID_DELTA_SCHEMES = ("grid_update", "grid_update_zlib", "grid_update_png")
BASELINE_SCHEMES = (*GRID_DELTA_SCHEMES, "keyframe_scans")
SCAN_QUANTUM_M = 0.01  # keyframe scans: ranges on this grid (the thesis lidar's sigma)
SCAN_HEADER = struct.Struct("<3f2fI")  # pose x, y, theta; angle_min, increment; beams
GRID_RESOLUTION_M = 0.05
BOUNDS_MARGIN_M = 1.0


@dataclass
class Keyframe:
    robot: str
    t_s: float
    scan: LaserScan
    pose: np.ndarray
    delta_bytes: int
    delta_zlib_bytes: int
    cells_bytes: int


@dataclass
class Recording:
    """Keyframes of one run and the final PolyMap of each robot.

    Every update is also decoded and applied to a receiver's copy of the robot's map, as
    the coordinator does: a merge or a correction (a loop closure's moved keyframes) is
    replayed (timed: the receiver's cost of the smaller messages) and must give the
    sender's cells bit for bit; one that does not is counted, and the receiver takes the
    cells (the coordinator would fetch the map)."""

    name: str
    keyframes: list[Keyframe] = field(default_factory=list)
    maps: dict[str, GridPolyMap] = field(default_factory=dict)
    mount: tuple[float, float, float] = (0.0, 0.0, 0.0)
    free_range_m: float = 3.0
    map_precision_m: float = 0.001  # whole maps are encoded at this grid (the config's)
    copies: dict[str, GridPolyMap] = field(default_factory=dict)
    atlases: dict[str, Atlas] = field(default_factory=dict)
    replay_ms: list[float] = field(default_factory=list)
    replay_failures: int = 0
    correction_ms: list[float] = field(default_factory=list)  # the receiver's, per correction
    correction_bytes: int = 0

    def add(
        self,
        robot: str,
        t_s: float,
        scan: LaserScan,
        pose,
        delta: MapDelta,
        op: MergeOp | None = None,
        correction: CorrectionOp | None = None,
    ) -> None:
        from protocols.mapcodec import encode_delta, encode_updates

        cells = encode_delta(delta)
        sent = encode_updates(delta, op, correction, cells)
        copy = self.copies.get(robot) or GridPolyMap(delta.cell_size)
        try:
            copy = self._receive(robot, copy, sent)
        except DeltaGapError:  # the coordinator would fetch the map: take the cells
            self.replay_failures += 1
            copy = (self.copies.get(robot) or GridPolyMap(delta.cell_size)).apply_delta(delta)
        self.copies[robot] = copy
        self.keyframes.append(
            Keyframe(
                robot,
                t_s,
                scan,
                np.asarray(pose, float),
                sum(len(m[3]) for m in sent),
                sum(len(zlib.compress(m[3])) for m in sent),
                len(cells),
            )
        )

    def _receive(self, robot: str, copy: GridPolyMap, sent) -> GridPolyMap:
        """The receiver's copy after the messages ``sent`` (as the coordinator applies
        them; its atlas of the robot's keyframes follows)."""
        from protocols.mapcodec import (
            CORRECTION_TYPE,
            MERGE_TYPE,
            decode_correction,
            decode_delta,
            decode_merge,
        )

        atlas = self.atlases.setdefault(robot, Atlas())
        for what, _, _, raw in sent:
            t0 = time.perf_counter()
            if what == MERGE_TYPE:
                op = decode_merge(raw)
                copy = copy.replay(op).map
                if op.keyframe is not None:
                    atlas.add(op.keyframe, op.polygon, op.options)
                self.replay_ms.append((time.perf_counter() - t0) * 1e3)
            elif what == CORRECTION_TYPE:
                self.correction_bytes += len(raw)
                copy, atlas, _ = replay_correction(copy, atlas, decode_correction(raw))
                self.atlases[robot] = atlas
                self.correction_ms.append((time.perf_counter() - t0) * 1e3)
            else:
                copy = copy.apply_delta(decode_delta(raw))
        return copy

    def copies_identical(self) -> bool:
        """Does every receiver's copy equal its robot's final map, cell for cell?"""
        return all(
            r in self.copies
            and set(m.cells) == set(self.copies[r].cells)
            and cells_digest(m.cells.values()) == cells_digest(self.copies[r].cells.values())
            for r, m in self.maps.items()
        )


def png_bytes(data: np.ndarray) -> int:
    """PNG size of a trinary grid as an 8-bit grey image (unknown 205, free 254, occupied 0,
    as map_server saves it)."""
    from PIL import Image

    img = np.full(data.shape, 205, dtype=np.uint8)
    img[data == 0] = 254
    img[data == 100] = 0
    buf = io.BytesIO()
    Image.fromarray(img[::-1]).save(buf, format="PNG", optimize=True)
    return buf.getbuffer().nbytes


def encode_keyframe_scan(scan: LaserScan, pose) -> bytes:
    """A keyframe as a collaborative SLAM system would share it: pose, beam angles and
    ranges in whole ``SCAN_QUANTUM_M`` (0: no valid return), each range sent as its
    difference to the previous beam's (int16), the whole zlib'd at level 9."""
    r = np.asarray(scan.ranges, dtype=float)
    ok = np.isfinite(r) & (r >= scan.range_min) & (r <= scan.range_max)
    q = np.where(ok, np.clip(np.round(r / SCAN_QUANTUM_M), 1, 32767), 0).astype(np.int32)
    diff = np.diff(q, prepend=0).astype(np.int16)
    head = SCAN_HEADER.pack(
        *(float(v) for v in pose), float(scan.angle_min), float(scan.angle_increment), len(q)
    )
    return zlib.compress(head + diff.tobytes(), 9)


def decode_keyframe_scan(raw: bytes) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(ranges in metres with 0 for no return, pose, angle_min, angle_increment)."""
    data = zlib.decompress(raw)
    x, y, th, a0, da, n = SCAN_HEADER.unpack_from(data)
    diff = np.frombuffer(data, dtype=np.int16, count=n, offset=SCAN_HEADER.size)
    q = np.cumsum(diff.astype(np.int32))
    return q * SCAN_QUANTUM_M, np.array([x, y, th]), a0, da


def _scan_bounds(kf: Keyframe, mount, free_range_m: float) -> tuple[float, float, float, float]:
    r = np.asarray(kf.scan.ranges, dtype=float)
    r = np.where(
        np.isfinite(r) & (r < kf.scan.range_max), r, np.where(np.isinf(r), free_range_m, 0)
    )
    x, y, th = kf.pose
    a = kf.scan.angles + th + mount[2]
    xs = np.concatenate([[x], x + r * np.cos(a)])
    ys = np.concatenate([[y], y + r * np.sin(a)])
    return xs.min(), ys.min(), xs.max(), ys.max()


def _keyframe_row(kf: Keyframe, g: CountingGrid, mount) -> dict:
    """The bytes of every scheme for one keyframe's update (the grid integrates its scan)."""
    from protocols.ros import encode_grid_update, encode_occupancy_grid

    g.integrate(kf.scan, kf.pose, mount)
    box = g.changes()
    full = g.trinary()
    full_raw = encode_occupancy_grid(full, g.res, g.origin, kf.t_s)
    row = {
        "t_s": kf.t_s,
        "robot": kf.robot,
        "polymap_delta": kf.delta_bytes,
        "polymap_delta_zlib": kf.delta_zlib_bytes,
        "polymap_cells": kf.cells_bytes,
        "grid_full": len(full_raw),
        "grid_full_zlib": len(zlib.compress(full_raw)),
        "grid_full_png": png_bytes(full),
        "grid_update": 0,
        "grid_update_zlib": 0,
        "grid_update_png": 0,
        "keyframe_scans": len(encode_keyframe_scan(kf.scan, kf.pose)),
        "known_m2": float((full != -1).sum()) * g.res**2,
    }
    if box is not None:
        upd = encode_grid_update(box.data, box.row0, box.col0, kf.t_s)
        row["grid_update"] = len(upd)
        row["grid_update_zlib"] = len(zlib.compress(upd))
        row["grid_update_png"] = png_bytes(box.data)
    return row


def measure(rec: Recording, progress: Callable[[int, int], None] | None = None) -> dict:
    """Bytes per scheme per keyframe; cumulative totals and final map sizes."""
    from protocols.mapcodec import encode_map

    if not rec.keyframes:
        raise ValueError(f"{rec.name}: no keyframes")
    b = np.array([_scan_bounds(k, rec.mount, rec.free_range_m) for k in rec.keyframes])
    bounds = (
        b[:, 0].min() - BOUNDS_MARGIN_M,
        b[:, 1].min() - BOUNDS_MARGIN_M,
        b[:, 2].max() + BOUNDS_MARGIN_M,
        b[:, 3].max() + BOUNDS_MARGIN_M,
    )
    grids = {
        r: CountingGrid(bounds, GRID_RESOLUTION_M, rec.free_range_m)
        for r in sorted({k.robot for k in rec.keyframes})
    }
    rows = []
    for n, kf in enumerate(rec.keyframes):
        rows.append(_keyframe_row(kf, grids[kf.robot], rec.mount))
        if progress:
            progress(n + 1, len(rec.keyframes))
    cumulative = {s: int(sum(r[s] for r in rows)) for s in SCHEMES}
    best_grid = min(GRID_DELTA_SCHEMES, key=lambda s: cumulative[s])
    best = min(BASELINE_SCHEMES, key=lambda s: cumulative[s])
    encoded = [encode_map(m, rec.map_precision_m) for m in rec.maps.values()]
    poly_map = sum(len(b) for b in encoded)
    poly_map_zlib = sum(len(zlib.compress(b)) for b in encoded)
    grid_png = sum(png_bytes(g.trinary()) for g in grids.values())
    known = sum(g.known_area_m2() for g in grids.values())
    return {
        "name": rec.name,
        "robots": len(grids),
        "keyframes": len(rows),
        "grid_cells": int(sum(g.size for g in grids.values())),
        "cumulative_bytes": cumulative,
        "best_grid_delta_scheme": best_grid,
        "best_baseline": best,
        "delta_bytes_ratio_vs_best_baseline": cumulative["polymap_delta"] / cumulative[best],
        "delta_bytes_ratio_vs_keyframe_scans": (
            cumulative["polymap_delta"] / cumulative["keyframe_scans"]
        ),
        "delta_bytes_ratio_vs_best_grid": cumulative["polymap_delta"] / cumulative[best_grid],
        "delta_zlib_bytes_ratio_vs_best_grid": (
            cumulative["polymap_delta_zlib"] / cumulative[best_grid]
        ),
        "final_map_bytes": {
            "polymap": poly_map,
            "polymap_zlib": poly_map_zlib,
            "grid_png": grid_png,
        },
        "map_bytes_ratio_vs_png": poly_map / grid_png,
        "cells_bytes_ratio_vs_best_grid": cumulative["polymap_cells"] / cumulative[best_grid],
        "merges_sent": len(rec.replay_ms),
        "corrections_sent": len(rec.correction_ms),
        "correction_bytes": rec.correction_bytes,
        "correction_bytes_share": rec.correction_bytes / max(cumulative["polymap_delta"], 1),
        "correction_replay_ms_p95": (
            float(np.percentile(rec.correction_ms, 95)) if rec.correction_ms else None
        ),
        "merges_not_replayed": rec.replay_failures,
        "receiver_copies_identical": rec.copies_identical(),
        "replay_ms_median": float(np.median(rec.replay_ms)) if rec.replay_ms else None,
        "replay_ms_p95": float(np.percentile(rec.replay_ms, 95)) if rec.replay_ms else None,
        "known_area_m2": known,
        "bytes_per_m2": {s: cumulative[s] / max(known, 1e-9) for s in SCHEMES},
        "rows": rows,
    }


# the shared recordings from real lidars (the simulated TurtleBot3 bag is left out)
REAL_BAGS = ("neato-office-1", "neato-square", "pioneer-hokuyo-corridor")

# --- recordings --------------------------------------------------------------------------------


def record_log(path: Path, cfg: Config, seed: int = 0) -> Recording:
    """PolySLAM over a CARMEN log with the default noisy odometry."""
    from polyswarm.io.carmen import read_carmen
    from polyswarm.slam.odometry import IncrementNoise, noisy_odometry
    from polyswarm.slam.polyslam import PolySlam

    log = read_carmen(path)
    ref = log.reference
    odom = noisy_odometry(ref, IncrementNoise(), seed)
    slam = PolySlam(cfg.slam, cfg.map.cell_size_m, initial_pose=ref[0])
    m = cfg.slam.mount
    rec = Recording(
        Path(path).name.split(".")[0],
        mount=(m.x_m, m.y_m, m.yaw_rad),
        free_range_m=cfg.slam.no_return_free_m,
        map_precision_m=cfg.map.whole_map_precision_m,
    )
    for k, s in enumerate(log.scans):
        step = slam.process(s.scan, odom[k])
        if step.delta is not None:
            rec.add("r1", float(s.stamp), s.scan, step.pose, step.delta, step.op, step.correction)
    rec.maps["r1"] = slam.map
    return rec


def record_bag(path: Path, cfg: Config) -> Recording:
    """PolySLAM over a recorded ROS bag with its own wheel odometry, as ``polyswarm slam``
    runs it (``runners.slam.run_bag``: the mount from tf, the driver's no-return value,
    evidence for a low-cost lidar): every keyframe's scan, delta and corrections."""
    from polyswarm.runners.slam import run_bag

    steps: list = []
    run, used = run_bag(path, cfg, on_step=steps.append)
    m = used.slam.mount
    rec = Recording(
        Path(path).stem,
        mount=(m.x_m, m.y_m, m.yaw_rad),
        free_range_m=used.slam.no_return_free_m,
        map_precision_m=used.map.whole_map_precision_m,
    )
    for stamp, scan, step in steps:
        if step.delta is not None:
            rec.add("r1", stamp, scan, step.pose, step.delta, step.op, step.correction)
    rec.maps["r1"] = run.slam.map
    return rec


def record_simulation(world: str, robots: int, sim_s: float, seed: int, cfg: Config) -> Recording:
    """A simulated exploration (in one process): every robot's keyframes."""
    from polyswarm.benchmarks.inproc import explore_in_process

    m = cfg.slam.mount
    rec = Recording(
        f"sim-{world.replace(':', '_')}-{robots}",
        mount=(m.x_m, m.y_m, m.yaw_rad),
        free_range_m=cfg.slam.no_return_free_m,
        map_precision_m=cfg.map.whole_map_precision_m,
    )
    run = explore_in_process(world, robots, sim_s, seed, cfg, on_keyframe=rec.add)
    rec.maps = {a.id: a.slam.map for a in run.agents}
    rec.name += f"-{run.sim_time_s:.0f}s"
    return rec


def write_outputs(res: dict, out: Path) -> None:
    """CSV of every update and PNG plots (cumulative bytes, bytes per square metre)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    rows = res["rows"]
    with open(out / f"{res['name']}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    t = np.array([r["t_s"] for r in rows])
    t = t - t[0]
    known = np.array([r["known_m2"] for r in rows])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.5))
    for s in SCHEMES:
        c = np.cumsum([r[s] for r in rows])
        ax1.plot(t, c, label=s, lw=2.5 if s.startswith("polymap") else 1.2)
        ax2.plot(known, c, label=s, lw=2.5 if s.startswith("polymap") else 1.2)
    ax1.set(xlabel="time (s)", ylabel="cumulative bytes", yscale="log", title=res["name"])
    ax2.set(xlabel="known area of the grid (m²)", ylabel="cumulative bytes", yscale="log")
    ax2.set_title("bytes against area mapped")
    ax1.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / f"{res['name']}.png", dpi=110)
    plt.close(fig)


def summary(results: list[dict]) -> dict:
    """The issue's keys: worst case over runs, and per run."""
    return {
        "delta_bytes_ratio_vs_best_baseline": max(
            r["delta_bytes_ratio_vs_best_baseline"] for r in results
        ),
        "delta_bytes_ratio_vs_best_grid": max(r["delta_bytes_ratio_vs_best_grid"] for r in results),
        "delta_bytes_ratio_vs_keyframe_scans": max(
            r["delta_bytes_ratio_vs_keyframe_scans"] for r in results
        ),
        "map_bytes_ratio_vs_png": max(r["map_bytes_ratio_vs_png"] for r in results),
        "cumulative_bytes": {r["name"]: r["cumulative_bytes"] for r in results},
        "runs": {r["name"]: {k: v for k, v in r.items() if k != "rows"} for r in results},
    }


def fmt_bytes(n: float) -> str:
    if n >= 1e6:
        return f"{n / 1e6:.1f} MB"
    if n >= 1e3:
        return f"{n / 1e3:.1f} kB"
    return f"{math.floor(n)} B"
