"""``polyswarm bench explore``: whole explorations, and the coordinator under 10 robots.

1. Explorations: ``polyswarm launch`` (every part its own process, Zenoh on loopback)
   per world x robot count x strategy x seed, with a robot profile
   (``polyswarm.profiles``); t99 (simulated seconds to 99 % of the free space the
   robots' footprint reaches, ``polyswarm.evaluation.coverage.reachable_free``), collisions,
   crashed processes, merged-map IoU and the reachable area left unexplored. Each is
   compared with the idealised reference (``polyswarm.benchmarks.reference``) run for
   the same world, robot count, start, sensor range, field of view, speed and radius:
   nothing is typed in.
2. Coordinator cycle with 10 robots: the agents, the simulator and the coordinator in one
   process (no Zenoh: the cycle is what is measured, not the transport), deltas passed
   through the wire codec; the coordinator's cycle time (merge + frontiers + costs +
   assignment) per cycle.
"""

from __future__ import annotations

import logging
import math
import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from polyswarm.config import Config

log = logging.getLogger(__name__)

REFERENCE_SLACK = 1.5  # our t99 may be at most this times the reference
MIN_IOU = 0.95  # a successful run's merged map against the world's free space
DATA_WORLDS = ("data:loop", "data:cross", "data:maze", "data:zigzag")
NEAREST_WORLDS = ("data:maze", "data:loop")  # where hungarian must beat nearest by 25%


@dataclass(frozen=True)
class RunSpec:
    world: str
    robots: int
    strategy: str
    seed: int
    profile: str = "thesis"
    start: str = "side-by-side"  # or "scattered" (told), "unknown" (scattered, not told)
    wrong_anchor: str = ""  # unknown starts: ROBOT:dx,dy,deg, its first frame sent that far off


def plan_runs(
    worlds: list[str],
    robots: list[int],
    seeds: int,
    nearest: bool,
    first_seed: int = 0,
    profile: str = "thesis",
    unknown_start: bool = False,
    wrong_anchor: str = "",
) -> list[RunSpec]:
    """World x robot count (hungarian) x seed (``first_seed`` .. ``first_seed + seeds -
    1``), plus 3-robot ``nearest`` on NEAREST_WORLDS. ``unknown_start``: instead, each
    world, robot count and seed twice from the same scattered starts, told and not told
    (with ``wrong_anchor``, a fault injection, in the runs not told)."""
    seed_range = range(first_seed, first_seed + seeds)
    if unknown_start:
        return [
            RunSpec(
                w, n, "hungarian", s, profile, start, wrong_anchor if start == "unknown" else ""
            )
            for w in worlds
            for n in robots
            for s in seed_range
            for start in ("scattered", "unknown")
        ]
    runs = [
        RunSpec(w, n, "hungarian", s, profile) for w in worlds for n in robots for s in seed_range
    ]
    if nearest:
        runs += [
            RunSpec(w, max(robots), "nearest", s, profile)
            for w in worlds
            if w in NEAREST_WORLDS and max(robots) > 1
            for s in seed_range
        ]
    return runs


def run_exploration(
    spec: RunSpec,
    out: Path,
    speed: float,
    wall_limit_s: float,
    base: Config | None = None,
    start_error: str = "",
) -> dict:
    """One launch; ``base``: the config the profile applies on (default: the defaults);
    ``start_error`` (ROBOT:dx,dy,deg): in runs with the starts told, one told that far off."""
    from polyswarm.config import Config, with_profile
    from polyswarm.runners.launch import LaunchOptions, launch

    opts = LaunchOptions(
        world=spec.world,
        robots=spec.robots,
        strategy=spec.strategy,
        seed=spec.seed,
        speed=speed,
        wall_limit_s=wall_limit_s,
        stop_coverage=0.99,  # t99 is what is measured; returning home is not
        out=out,
        config=with_profile(base or Config(), spec.profile),
        scatter=spec.start == "scattered",
        unknown_start=spec.start == "unknown",
        wrong_anchor=spec.wrong_anchor,
        start_error=start_error if spec.start != "unknown" else "",
    )
    m = launch(opts).metrics
    row = {
        "world": spec.world,
        "robots": spec.robots,
        "strategy": spec.strategy,
        "seed": spec.seed,
        "profile": spec.profile,
        "start": spec.start,
        "wrong_anchor": spec.wrong_anchor,
        "start_error": opts.start_error,
        "anchors": m["anchors"],
        "anchor_events": m.get("anchor_events", []),
        "pose_error_m": m.get("pose_error_m", {}),
        "unanchored": m["unanchored"],
        "t90_s": m["t90_s"],
        "t99_s": m["t99_s"],
        "final_coverage": m["final_coverage"],
        "unexplored_reachable_m2": m["unexplored_reachable_m2"],
        "map_iou": m["map_iou"],
        "phantom_obstacle_m": m.get("phantom_obstacle_m"),
        "wall_collisions": m["collisions"]["walls"],
        "robot_collisions": m["collisions"]["robots"],
        "crashed_processes": m["crashed_processes"],
        "wall_time_s": m["wall_time_s"],
        "coordinator_cycle_p95_ms": m["coordinator_cycle_p95_ms"],
        "bytes_sent_per_robot": m["bytes_sent_per_robot"],
        "out": str(out),
    }
    row["success"] = succeeded(row)
    return row


def succeeded(row: dict) -> bool:
    """99 % reached, no collision, no crashed process, the merged map right."""
    return bool(
        row["t99_s"] is not None
        and row["wall_collisions"] == 0
        and row["robot_collisions"] == 0
        and not row["crashed_processes"]
        and (row["map_iou"] or 0.0) >= MIN_IOU
    )


def reference_t99(spec: RunSpec) -> float | None:
    """The reference's t99 for a run's world, robots, profile and start (cached)."""
    from polyswarm.benchmarks.reference import reference_run
    from polyswarm.config import Config, with_profile
    from polyswarm.evaluation.coverage import coverage_tolerance
    from sim import load_world, spread_start_poses

    cfg = with_profile(Config(), spec.profile)
    world = load_world(spec.world, seed=spec.seed)
    start = spread_start_poses(world, spec.robots, cfg.sim.robot.radius_m)[0]
    lid = cfg.sim.lidar
    res = world.grid.resolution if world.grid is not None else 0.0
    tol = coverage_tolerance(lid.noise_sigma_m, lid.noise_sigma_per_m, res)
    return reference_run(spec.world, spec.robots, cfg, start[:2], tol, seed=spec.seed)["t99_s"]


def _median_or_none(values: list[float | None]) -> float | None:
    """Median t99 over seeds; a run that never reached 99% makes the median undefined
    only if it is the majority (it counts as +inf)."""
    if not values:
        return None
    v = sorted(math.inf if x is None else x for x in values)
    med = statistics.median(v)
    return None if math.isinf(med) else float(med)


def summarise(rows: list[dict], references: dict | None = None) -> dict:
    """Per profile, world and robot count (hungarian): t99 per seed and its median, the
    reference and the ratios (median and worst), success rate, the reachable area left
    unexplored at worst; and the 3-against-1-robot and hungarian-against-nearest ratios."""
    references = references or {}
    per: dict = {}
    for r in rows:
        if r["strategy"] != "hungarian":
            continue
        cell = per.setdefault(r.get("profile", "thesis"), {}).setdefault(r["world"], {})
        cell.setdefault(str(r["robots"]), []).append(r)
    profiles: dict = {}
    for prof, worlds in per.items():
        for w, by_n in worlds.items():
            for n, runs in by_n.items():
                rs = sorted(runs, key=lambda r: r["seed"])
                t99 = [r["t99_s"] for r in rs]
                med = _median_or_none(t99)
                # each run against the reference's run on its own seed's layout
                refs = [references.get((prof, w, int(n), r["seed"])) for r in rs]
                ref = _median_or_none(refs) if all(refs) else None
                ratios = [
                    None if t is None or not f else t / f for t, f in zip(t99, refs, strict=True)
                ]
                profiles.setdefault(prof, {}).setdefault(w, {})[n] = {
                    "t99_s": t99,
                    "t99_median_s": med,
                    "reference_t99_s": ref,
                    "t99_ratio_vs_reference": None if med is None or not ref else med / ref,
                    "t99_ratio_vs_reference_worst": (
                        None if any(x is None for x in ratios) or not ratios else max(ratios)
                    ),
                    "success_rate": sum(r.get("success", False) for r in rs) / len(rs),
                    "unexplored_reachable_m2_max": max(r["unexplored_reachable_m2"] for r in rs),
                    "map_iou_min": min(r["map_iou"] for r in rs),
                    # walls where there are none (a misplaced map's ghosts), worst run, m
                    "phantom_obstacle_m_max": _max_or_none(r.get("phantom_obstacle_m") for r in rs),
                    # the robots' poses against ground truth: the worst robot's median
                    "pose_err_m_median_max": _max_or_none(
                        e["median"] for r in rs for e in r.get("pose_error_m", {}).values()
                    ),
                }
    groups: dict = {}  # (world, robots, strategy) -> t99 of every run
    for r in rows:
        groups.setdefault((r["world"], r["robots"], r["strategy"]), []).append(r["t99_s"])
    t99 = {key: _median_or_none(v) for key, v in groups.items()}
    ratio_3_vs_1, ratio_vs_nearest = {}, {}
    for w in {k[0] for k in t99}:
        one, three, near = (
            t99.get((w, 1, "hungarian")),
            t99.get((w, 3, "hungarian")),
            t99.get((w, 3, "nearest")),
        )
        if one and three:
            ratio_3_vs_1[w] = three / one
        if three and near:
            ratio_vs_nearest[w] = three / near
    ious = [r["map_iou"] for r in rows if r["map_iou"] is not None]
    return {
        "runs": len(rows),
        "success_rate": (sum(r.get("success", False) for r in rows) / len(rows) if rows else None),
        "profiles": profiles,
        "t99_ratio_3_vs_1": ratio_3_vs_1,
        "t99_ratio_vs_nearest": ratio_vs_nearest,
        "map_iou_min": min(ious) if ious else None,
        "unexplored_reachable_m2_max": max(
            (r["unexplored_reachable_m2"] for r in rows), default=None
        ),
        "wall_collisions": sum(r["wall_collisions"] for r in rows),
        "crashed_runs": sum(bool(r["crashed_processes"]) for r in rows),
        "wall_time_s_max": {
            w: max(r["wall_time_s"] for r in rows if r["world"] == w)
            for w in {r["world"] for r in rows}
        },
    }


WRONG_FRAME_M, WRONG_FRAME_DEG = 1.0, 5.0  # an anchor this far off is a wrong merge
FRAME_TARGET_M, FRAME_TARGET_DEG = 0.10, 1.0  # the frame error
UNKNOWN_SLACK = 1.3  # t99 with unknown starts at most this times the told starts' t99


def summarise_unknown(rows: list[dict]) -> dict:
    """Unknown against told starts, per profile, world and robot count, over the seeds:
    success of the unknown runs, robots never anchored, anchors' errors and wrong ones,
    and the t99 ratio (unknown / told, same seed and starts; median and worst)."""
    told = {
        (r["profile"], r["world"], r["robots"], r["seed"]): r
        for r in rows
        if r["start"] == "scattered"
    }
    out: dict = {}
    for r in rows:
        if r["start"] != "unknown":
            continue
        key = (r["profile"], r["world"], r["robots"])
        cell = out.setdefault(key, {"runs": []})
        base = told.get((*key, r["seed"]))
        errs = list(r["anchors"].values())
        cell["runs"].append(
            {
                "seed": r["seed"],
                "t99_s": r["t99_s"],
                "told_t99_s": base["t99_s"] if base else None,
                "ratio": (r["t99_s"] / base["t99_s"])
                if base and r["t99_s"] and base["t99_s"]
                else None,
                "success": r["success"],
                "unanchored": r["unanchored"],
                "frame_err_m_max": max((a["err_m"] for a in errs), default=None),
                "frame_err_deg_max": max((a["err_deg"] for a in errs), default=None),
                "wrong": sum(
                    a["err_m"] > WRONG_FRAME_M or a["err_deg"] > WRONG_FRAME_DEG for a in errs
                ),
                # every frame sent, also those later withdrawn, and the withdrawals
                "wrong_sent": sum(
                    e["err_m"] > WRONG_FRAME_M or e["err_deg"] > WRONG_FRAME_DEG
                    for e in r.get("anchor_events", [])
                    if not e["own"] and not e.get("team")
                ),
                # waiting robots placed in each other's frames (``agents.anchoring``)
                "teamed": sum(bool(e.get("team")) for e in r.get("anchor_events", [])),
                "undone": sum(e["own"] for e in r.get("anchor_events", [])),
                # the robots' poses in the shared frame against ground truth: the worst
                # robot's median and 95th percentile (metres)
                "pose_err_m_median": max(
                    (e["median"] for e in r.get("pose_error_m", {}).values()), default=None
                ),
                "pose_err_m_p95": max(
                    (e["p95"] for e in r.get("pose_error_m", {}).values()), default=None
                ),
                "told_pose_err_m_p95": max(
                    (e["p95"] for e in base.get("pose_error_m", {}).values()), default=None
                )
                if base
                else None,
                "map_iou": r.get("map_iou"),
                "told_map_iou": base.get("map_iou") if base else None,
            }
        )
    res = {}
    for (prof, world, n), cell in out.items():
        runs = cell["runs"]
        ratios = [x["ratio"] for x in runs]
        res.setdefault(prof, {}).setdefault(world, {})[str(n)] = {
            "runs": runs,
            "success_rate": sum(x["success"] for x in runs) / len(runs),
            "all_anchored": all(not x["unanchored"] for x in runs),
            "wrong_merges": sum(x["wrong"] for x in runs),
            "wrong_frames_sent": sum(x["wrong_sent"] for x in runs),
            "merges_undone": sum(x["undone"] for x in runs),
            # None where no robot was placed in any run (not 0 m)
            "frame_err_m_max": _max_or_none(x["frame_err_m_max"] for x in runs),
            "frame_err_deg_max": _max_or_none(x["frame_err_deg_max"] for x in runs),
            "t99_ratio_median": _median_or_none(ratios),
            "t99_ratio_worst": None if any(x is None for x in ratios) else max(ratios),
            "pose_err_m_p95_max": max(
                (x["pose_err_m_p95"] for x in runs if x["pose_err_m_p95"] is not None),
                default=None,
            ),
        }
    return res


def _max_or_none(values) -> float | None:
    return max((v for v in values if v is not None), default=None)


def run(
    worlds: list[str],
    robots: list[int],
    seeds: int,
    nearest: bool,
    speed: float,
    wall_limit_s: float,
    out: Path | None,
    load_robots: int,
    load_sim_s: float,
    on_run: Callable[[int, int, RunSpec, dict | None], None] | None = None,
    first_seed: int = 0,
    profiles: tuple[str, ...] = ("thesis",),
    unknown_start: bool = False,
    wrong_anchor: str = "",
    base: Config | None = None,
    start_error: str = "",
) -> dict:
    out = out or Path(tempfile.mkdtemp(prefix="polyswarm-bench-explore-"))
    runs = [
        spec
        for prof in profiles
        for spec in plan_runs(
            worlds, robots, seeds, nearest, first_seed, prof, unknown_start, wrong_anchor
        )
    ]
    rows, references = [], {}
    for k, spec in enumerate(runs):
        if on_run:
            on_run(k, len(runs), spec, None)
        key = (spec.profile, spec.world, spec.robots, spec.seed)  # seeded layouts differ
        if spec.strategy == "hungarian" and spec.start == "side-by-side" and key not in references:
            references[key] = reference_t99(spec)
        name = f"{spec.profile}-{spec.world.replace(':', '_')}-{spec.robots}-{spec.strategy}"
        name += "" if spec.start == "side-by-side" else f"-{spec.start}"
        t0 = time.monotonic()
        row = run_exploration(
            spec, out / f"{name}-{spec.seed}", speed, wall_limit_s, base, start_error
        )
        row["reference_t99_s"] = references.get(key)
        log.info("%s: t99 %s s in %.0f s wall", spec, row["t99_s"], time.monotonic() - t0)
        rows.append(row)
        if on_run:
            on_run(k, len(runs), spec, row)
    res = summarise([r for r in rows if r["start"] == "side-by-side"], references)
    if unknown_start:
        res["unknown_start"] = summarise_unknown(rows)
    res["runs_detail"] = rows
    res["out"] = str(out)
    if load_robots > 0:
        from polyswarm.benchmarks.cycle import coordinator_cycles

        load = coordinator_cycles(robots=load_robots, sim_s=load_sim_s)
        res["coordinator_load"] = load
        res[f"coordinator_cycle_p95_ms_{load_robots}_robots"] = load["cycle_p95_ms"]
    return res
