"""The launch's observer: it listens to everything the swarm says (never to what it is
told) and to the simulator's ground truth, and measures the exploration: coverage over
time, the merged map against the world, the robots' poses against the truth, bytes,
the coordinator's cycle, memory; and writes the run's outputs."""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import shapely
import shapely.affinity

from agents.leadership import Following
from polyswarm.config import Config, known_starts
from polyswarm.errors import MapError
from polyswarm.evaluation.coverage import coverage_tolerance, reachable_free, time_to_coverage
from polyswarm.evaluation.maps import map_iou, phantom_obstacles
from polyswarm.frames.mapmatch import frame_error
from polyswarm.polymap import GridPolyMap, MapDelta, VectorType
from polyswarm.runners import netns
from polyswarm.runners.children import Child, _rss_mb
from polyswarm.se2 import compose, inverse, transform_points
from protocols.chunks import MapChunk
from protocols.keys import SwarmKeys
from protocols.mapcodec import decode_delta
from protocols.messages import (
    Anchor,
    Clock,
    CoordinatorStatus,
    MissionState,
    Pose,
    RobotStatus,
    Truth,
)

if TYPE_CHECKING:  # the options the launch was given
    from polyswarm.runners.launch import LaunchOptions

log = logging.getLogger(__name__)

COVERAGE_EVERY_S = 1.0  # simulated seconds between coverage samples
PHANTOM_M = 0.3  # an obstacle vector this far from every true wall is no wall


@dataclass
class RobotView:
    state: str = "starting"
    target: int = -1
    bytes_sent: int = 0
    map_delta_bytes: int = 0
    keyframes: int = 0
    truth: list = field(default_factory=list)  # (t, x, y, theta)
    estimate: list = field(default_factory=list)
    path_length_m: float = 0.0


def _clip(geom, bounds):
    """``geom`` inside the box ``bounds``, by the general overlay. GEOS's fast rectangle
    clip is not robust here: on the 10-robot maze's reachable free space it raised on 20
    cells ("Invalid number of points in LinearRing found 3", which ended a run) and gave
    0.18 m2 for a cell holding 3.82 m2. Each cell is clipped once (cached)."""
    return shapely.intersection(geom, shapely.box(*bounds))


def _moved(geom, pose):
    """``geom`` moved rigidly by ``pose`` (x m, y m, theta rad)."""
    if not np.any(pose):
        return geom
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return shapely.affinity.affine_transform(geom, [c, -s, s, c, pose[0], pose[1]])


class Observer:
    """Follows the exploration from the outside: coverage, states, bytes, trajectories."""

    def __init__(self, world, cfg: Config, ids: list[str]) -> None:
        self.world = world
        self.outages = netns.Outages()  # links cut (launch --netns)
        self.following = Following()  # the active coordinator, as the robots see it
        self.leaders: list[list] = []  # [term, name, sim s, wall s] as the leader changed
        self.coordinator_lost: list[float] = []  # wall s: active coordinators killed
        # coverage counts the free space the robots' footprint can reach, less a band of
        # the lidar's noise along walls (polyswarm.evaluation.coverage.reachable_free); the map's
        # IoU is taken against all free space
        lid = cfg.sim.lidar
        res = world.grid.resolution if world.grid is not None else 0.0
        self.tolerance_m = coverage_tolerance(lid.noise_sigma_m, lid.noise_sigma_per_m, res)
        starts = list(cfg.sim.start_poses) or [r.start for r in cfg.robots] or [world.start]
        self.truth_free = reachable_free(
            world.free, cfg.sim.robot.radius_m, starts, self.tolerance_m
        )
        # robots whose starts were not given map in the first robot's frame: the truth is
        # taken into it (the world as the map sees it)
        # robots in frames of their own until anchored: their poses are not compared yet
        self.own_frames = {rid for rid, st in known_starts(cfg.robots).items() if st is None}
        self.true_starts = [np.asarray(p, dtype=float) for p in cfg.sim.start_poses]
        self.anchors: dict[str, dict] = {}  # robot -> when its frame was placed, how well
        # every anchor sent (withdrawals, ``own``, among them), and per robot the last
        # one's number and where its first frame lies in the coordinates it speaks now
        self.anchor_events: list[dict] = []
        self._frames: dict[str, tuple[int, np.ndarray]] = {}
        self.to_map = np.zeros(3)
        if cfg.sim.start_poses and any(r.start is None for r in cfg.robots):
            self.to_map = inverse(np.asarray(starts[0], dtype=float))
        self.truth_free = _moved(self.truth_free, self.to_map)
        self.world_free = _moved(world.free, self.to_map)
        ws, we = world.wall_segments
        self.walls = (transform_points(self.to_map, ws), transform_points(self.to_map, we))
        self.truth_area = float(self.truth_free.area)
        shapely.prepare(self.truth_free)
        self.merged = GridPolyMap(cfg.map.cell_size_m)
        self.robots = {rid: RobotView() for rid in ids}
        self.sim_t = 0.0
        self.sim_speed = 0.0
        self.mission = MissionState.STARTING
        self.coordinator: CoordinatorStatus | None = None
        # robot map updates lost in transit as the coordinator saw them: gaps, map
        # fetches, their bytes; summed over coordinator restarts (each counts from 0)
        self.losses = np.zeros(3, dtype=np.int64)
        self._losses_now = np.zeros(3, dtype=np.int64)
        self.cycle_ms: list[float] = []
        self.cycle_cpu_ms: list[float] = []
        self.coverage: list[tuple[float, float]] = []
        self.collisions = (0, 0)
        self._cell_cover: dict = {}  # cell index -> (cell version, covered m2)
        self._truth_cells: dict = {}
        self.need_resync = False
        # every process's resident memory: name -> [(wall s, MB, the robot's keyframes)]
        self.rss_mb: dict[str, list[tuple[float, float, int]]] = {}
        self._behind: float | None = None

    # coverage = explored space inside the reachable free space, over its area
    def covered_area(self) -> float:
        total = 0.0
        for ix, cell in self.merged.cells.items():
            cached = self._cell_cover.get(ix)
            if cached is None or cached[0] is not cell:
                truth = self._truth_cells.get(ix)
                if truth is None:
                    truth = self._truth_cells[ix] = _clip(self.truth_free, cell.bounds)
                area = float(shapely.intersection(cell.region, truth).area) if cell.polygons else 0
                cached = self._cell_cover[ix] = (cell, area)
            total += cached[1]
        return total

    def coverage_now(self) -> float:
        return self.covered_area() / max(self.truth_area, 1e-9)

    def iou(self) -> float:
        return map_iou(self.merged.explored_region(), self.world_free)

    def phantom_m(self) -> float:
        st, en, _ = self.merged.vectors([VectorType.OBSTACLE])
        return phantom_obstacles(st, en, *self.walls, PHANTOM_M)

    def on_merged(self, delta: MapDelta) -> None:
        self.merged = self.merged.apply_delta(delta)

    def on_anchor(self, rid: str, a: Anchor) -> None:
        """The coordinator placed robot ``rid``'s frame (or withdrew it: ``own``): scored
        against where it really started (resends repeat an anchor: counted once)."""
        k = next((i for i, r in enumerate(self.robots) if r == rid), None)
        last, first = self._frames.get(rid, (0, np.zeros(3)))
        if k is None or a.frame <= last or k >= len(self.true_starts):
            return
        event = {"robot": rid, "frame": a.frame, "t_s": self.sim_t, "own": a.own}
        if a.own:  # withdrawn: its map left the merged map, its coordinates are its own
            self.anchors.pop(rid, None)
        elif a.team:  # into another waiting robot's frame: scored once the team is placed
            first = compose((a.x, a.y, a.theta), first)
            event["team"] = True
        else:
            first = compose((a.x, a.y, a.theta), first)
            truth = compose(self.to_map, self.true_starts[k])
            err_m, err_rad = frame_error(first, truth)
            place = {"t_s": self.sim_t, "err_m": err_m, "err_deg": math.degrees(err_rad)}
            self.anchors[rid] = place
            event |= place
        self._frames[rid] = (a.frame, first)
        self.anchor_events.append(event)

    def pose_errors(self) -> dict[str, dict]:
        """Each robot's pose as it sent it against ground truth (the truth sample nearest
        in time), over the poses it sent in the shared frame: median, 95th percentile
        and last position error (metres)."""
        out = {}
        for rid, v in self.robots.items():
            if not v.estimate or not v.truth:
                continue
            tt = np.array([t[0] for t in v.truth])
            est = np.array(v.estimate)
            k = np.clip(np.searchsorted(tt, est[:, 0]), 0, len(tt) - 1)
            k0 = np.clip(k - 1, 0, len(tt) - 1)
            k = np.where(np.abs(tt[k0] - est[:, 0]) < np.abs(tt[k] - est[:, 0]), k0, k)
            truth = np.array([v.truth[i][1:3] for i in k])
            err = np.hypot(*(est[:, 1:3] - truth).T)
            out[rid] = {
                "median": float(np.median(err)),
                "p95": float(np.percentile(err, 95)),
                "end": float(err[-1]),
            }
        return out

    def unplaced(self) -> list[str]:
        """Robots in frames of their own whose frames were not placed yet."""
        return sorted((self.own_frames & set(self.robots)) - set(self.anchors))

    def sample(self) -> None:
        if not self.coverage or self.sim_t - self.coverage[-1][0] >= COVERAGE_EVERY_S:
            self.coverage.append((self.sim_t, self.coverage_now()))

    def _leader(self, msg: CoordinatorStatus) -> bool:
        """Whether ``msg`` comes from the leader (chosen as robots choose it,
        ``agents.leadership.Following``); a new one is recorded, and its merged map
        fetched whole."""
        if not msg.leader:
            return True
        before = self.following.leader
        self.following.heard(msg)
        now = self.following.leader
        if now != before:
            self.leaders.append([*now, round(self.sim_t, 2), round(time.monotonic(), 3)])
            self.need_resync = self.need_resync or before is not None
        return now == (msg.term, msg.leader)

    def handle(self, keys: SwarmKeys, item) -> None:
        msg = item.msg
        rid = keys.robot_of(item.key)
        if isinstance(msg, Anchor):
            self.on_anchor(item.key.rsplit("/", 1)[-1], msg)
        elif isinstance(msg, Clock):
            self.sim_t, self.sim_speed = msg.t_s, msg.speed
        elif isinstance(msg, Truth):
            self.collisions = (msg.wall_collisions, msg.robot_collisions)
            for name, true_pose in msg.poses.items():
                view = self.robots.get(name)
                if view is None:
                    continue
                p = compose(self.to_map, true_pose)
                if view.truth:
                    view.path_length_m += math.hypot(
                        p[0] - view.truth[-1][1], p[1] - view.truth[-1][2]
                    )
                view.truth.append((item.stamp_s, *p))
        elif isinstance(msg, CoordinatorStatus):
            if not self._leader(msg):
                return  # a coordinator that lost the election, until it steps down
            self.coordinator = msg
            self.mission = msg.state
            now = np.array([msg.gaps, msg.fetches, msg.fetch_bytes], dtype=np.int64)
            if (now < self._losses_now).any():  # a restarted coordinator counts from 0
                self.losses += self._losses_now
            self._losses_now = now
            self.cycle_ms.append(msg.cycle_ms)
            self.cycle_cpu_ms.append(msg.cycle_cpu_ms)
            if msg.map_version > self.merged.version:  # a late or lost delta
                self._behind = self._behind if self._behind is not None else time.monotonic()
                if time.monotonic() - self._behind > 1.0:
                    self.need_resync, self._behind = True, None
            else:
                self._behind = None
        elif rid in self.robots:
            view = self.robots[rid]
            if isinstance(msg, RobotStatus):
                view.state, view.target = str(msg.state), msg.target
                view.bytes_sent, view.keyframes = msg.bytes_sent, msg.keyframes
                self.outages.status(rid, self.sim_t, msg.keyframes)
            elif isinstance(msg, Pose) and (
                rid not in self.own_frames or (msg.frame > 0 and not msg.own)
            ):
                view.estimate.append((item.stamp_s, msg.x, msg.y, msg.theta))
            elif isinstance(msg, MapChunk) and item.payload is not None:
                view.map_delta_bytes += len(item.payload)
        elif isinstance(msg, MapChunk) and item.payload is not None:  # the merged map
            try:
                self.on_merged(decode_delta(item.payload))
            except MapError:
                self.need_resync = True

    def sample_memory(self, children: list[Child], wall_s: float) -> None:
        for child in children:
            rss = _rss_mb(child)
            if rss is not None:
                view = self.robots.get(child.name)
                kf = view.keyframes if view is not None else 0
                self.rss_mb.setdefault(child.name, []).append((wall_s, rss, kf))

    def metrics(self, wall_s: float, opts: LaunchOptions) -> dict:
        cov = self.coverage

        return {
            "world": self.world.name,
            "robots": len(self.robots),
            "strategy": opts.strategy,
            "seed": opts.seed,
            "mission_state": str(self.mission),
            "coverage_over_time": [[round(t, 2), round(c, 5)] for t, c in cov],
            "t90_s": time_to_coverage(cov, 0.90),
            "t99_s": time_to_coverage(cov, 0.99),
            "final_coverage": cov[-1][1] if cov else 0.0,
            "unexplored_reachable_m2": self.truth_area - self.covered_area(),
            "reachable_free_m2": self.truth_area,
            "coverage_tolerance_m": self.tolerance_m,
            "sim_time_s": self.sim_t,
            "total_path_length_m": sum(v.path_length_m for v in self.robots.values()),
            "per_robot_path_length_m": {k: v.path_length_m for k, v in self.robots.items()},
            "bytes_sent_per_robot": {k: v.bytes_sent for k, v in self.robots.items()},
            "map_delta_bytes_per_robot": {k: v.map_delta_bytes for k, v in self.robots.items()},
            "keyframes_per_robot": {k: v.keyframes for k, v in self.robots.items()},
            "map_iou": self.iou(),
            # walls in the map where there are none (a robot mapped as a wall, a ghost of a
            # misaligned view): obstacle vectors farther than PHANTOM_M from any true wall
            "phantom_obstacle_m": self.phantom_m(),
            "collisions": {"walls": self.collisions[0], "robots": self.collisions[1]},
            "coordinator_cycle_p95_ms": (
                float(np.percentile(self.cycle_ms, 95)) if self.cycle_ms else None
            ),
            "coordinator_cycle_cpu_p95_ms": (
                float(np.percentile(self.cycle_cpu_ms, 95)) if self.cycle_cpu_ms else None
            ),
            "merged_map_bytes": None,
            # robot map updates the coordinator saw lost or late in transit, and the
            # whole-map fetches (and bytes) that healed them
            "robot_map_gaps": int(self.losses[0] + self._losses_now[0]),
            "robot_map_fetches": int(self.losses[1] + self._losses_now[1]),
            "robot_map_fetch_bytes": int(self.losses[2] + self._losses_now[2]),
            "wall_time_s": wall_s,
            # robots whose starts nobody gave: when and how well their frames were placed,
            # and those never placed (their maps never joined the merged map)
            "anchors": self.anchors,
            "unanchored": self.unplaced(),
            "anchor_events": self.anchor_events,  # every anchor and withdrawal, in order
            # poses sent against ground truth, in the shared frame (metres)
            "pose_error_m": self.pose_errors(),
            # resident memory of every process over the run (wall s, MB; an agent's row
            # also has its keyframes then, to tell memory that follows the map from a leak)
            "rss_mb_over_time": {
                name: [[round(t, 1), round(m, 1), kf] for t, m, kf in rows]
                for name, rows in self.rss_mb.items()
            },
        }


# --- processes ----------------------------------------------------------------------------------


def _write_outputs(out: Path, obs: Observer, m: dict, precision_m: float) -> None:
    from polyswarm.io.export import export_map
    from polyswarm.io.tum import write_tum
    from protocols.files import write_polymap

    m["merged_map_bytes"] = write_polymap(obs.merged, out / "map.polymap", precision_m)
    trajs = [np.array(v.truth)[:, 1:3] for v in obs.robots.values() if len(v.truth) > 1]
    export_map(obs.merged, out / "map.svg", trajectories=trajs)
    export_map(obs.merged, out / "map.png", trajectories=trajs)
    tdir = out / "trajectories"
    tdir.mkdir(exist_ok=True)
    for rid, v in obs.robots.items():
        for name, rows in ((rid, v.estimate), (f"{rid}_truth", v.truth)):
            if rows:
                a = np.array(rows)
                write_tum(tdir / f"{name}.tum", a[:, 0], a[:, 1:4])
    _coverage_plot(out / "coverage.png", obs, m)
    (out / "metrics.json").write_text(json.dumps(m, indent=2, default=float))


def _coverage_plot(path: Path, obs: Observer, m: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    if obs.coverage:
        t, c = np.array(obs.coverage).T
        ax.plot(t, 100 * c, color="#1f3fbf")
    for key, frac in (("t90_s", 90), ("t99_s", 99)):
        if m.get(key) is not None:
            ax.axvline(m[key], color="#999999", linestyle="--", linewidth=0.8)
            ax.text(m[key], 2, f" {frac}%: {m[key]:.0f} s", fontsize=8)
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel("coverage of reachable free space (%)")
    ax.set_ylim(0, 101)
    ax.set_title(f"{m['world']}: {m['robots']} robot(s), {m['strategy']}")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
