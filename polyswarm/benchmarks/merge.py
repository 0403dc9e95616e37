"""``polyswarm bench merge``: merging maps of robots whose start poses nobody measured.

Each run explores a world with robots at scattered random starts (``sim``'s
``scattered_start_poses``: seeded, 10 m apart where the world allows, random headings).
Every ``SNAPSHOT_S`` simulated seconds each robot's map is taken in the robot's own
frame (its start is its origin), and robot k's map is matched against robot 1's by

* polyswarm's ``match_maps`` (search, ICP, free-space verification; ``mapmatch``), with
  the robots' sightings up to that moment (``sighting``: each agent sends its scan's clear
  profile with a pose a second, as robots do while a frame is unknown), and the
  ``FrameEstimate`` that commits a frame once successive matches agree and the robots
  saw each other where it puts them. These recorded robots explore without the
  coordinator's rendezvous (a launch sends a waiting robot towards where its candidate
  frame puts the nearest other): their sightings are the ones exploration gives;
* the peer method, ``multirobot_map_merge``'s feature-based grid merging
  (``gridmerge``: AKAZE, its hard-coded choice, and ORB) on the same maps rasterised at
  5 cm, at several confidence thresholds (its default is 1.0), so that its best
  setting is in the table.

Ground truth (the true starts) is used only to score: a frame within
``CORRECT_M`` / ``CORRECT_RAD`` is correct, beyond ``WRONG_M`` or ``WRONG_RAD`` wrong.
A pair "overlaps" at a moment when the two maps, placed by the true frames, share at
least ``mapmatch.MIN_OVERLAP_M2`` of explored space; it is merged from the first moment
a method gives a frame that is not wrong, and its final frame is the one it gives at
the run's last moment.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

SNAPSHOT_S = 5.0  # simulated seconds between the moments both methods are run at
SIM_LIMIT_S = 600.0  # each exploration stops at 99 % coverage or this (simulated s)
CORRECT_M, CORRECT_RAD = 0.10, math.radians(1.0)  # the final frame error
WRONG_M, WRONG_RAD = 1.0, math.radians(5.0)  # an accepted frame this far off is wrong
GRID_THRESHOLDS = (0.3, 0.5, 1.0, 1.5)  # the peer method's estimation_confidence


def _snapshots(world: str, seed: int, robots: int, cfg) -> tuple[list, list, list]:
    """(moments [(t s, [robot maps in their own frames])], true starts, each robot's
    track of poses and clear profiles in its own frame)."""
    from polyswarm.benchmarks.inproc import explore_in_process
    from polyswarm.frames.mapmatch import transform_map
    from polyswarm.frames.sighting import Sighting, Track
    from polyswarm.se2 import compose, inverse
    from sim import load_world, scattered_start_poses

    starts = scattered_start_poses(
        load_world(world, seed=seed), robots, cfg.sim.robot.radius_m, seed
    )
    moments: list = []
    due = [SNAPSHOT_S]
    tracks = [Track() for _ in range(robots)]

    def on_pose(k: int, t: float, pose) -> None:
        own = compose(inverse(np.asarray(starts[k])), (pose.x, pose.y, pose.theta))
        tracks[k].add(Sighting(t, tuple(float(v) for v in own), pose.clear))

    def on_step(sim, agents, _coord) -> None:
        if sim.time >= due[0]:
            due[0] += SNAPSHOT_S
            maps = [a.slam.map for a in agents]
            moments.append((sim.time, maps))

    explore_in_process(
        world,
        robots,
        SIM_LIMIT_S,
        seed,
        cfg,
        on_step=on_step,
        stop_coverage=0.99,
        start_poses=starts,
        on_pose=on_pose,
        sightings=True,
    )
    own = [
        (t, [transform_map(m, inverse(np.asarray(s))) for m, s in zip(maps, starts, strict=True)])
        for t, maps in moments
    ]
    return own, starts, tracks


def _true_overlap(a, b, pose) -> float:
    import shapely
    import shapely.affinity

    c, s = math.cos(pose[2]), math.sin(pose[2])
    moved = shapely.affinity.affine_transform(b.explored_region(), [c, -s, s, c, pose[0], pose[1]])
    return float(shapely.intersection(a.explored_region(), moved).area)


def _score(est, truth) -> dict:
    from polyswarm.frames.mapmatch import frame_error

    if est is None:
        return {"err_m": None, "err_deg": None, "correct": False, "wrong": False}
    e_m, e_rad = frame_error(est, truth)
    return {
        "err_m": e_m,
        "err_deg": math.degrees(e_rad),
        "correct": e_m <= CORRECT_M and e_rad <= CORRECT_RAD,
        "wrong": e_m > WRONG_M or e_rad > WRONG_RAD,
    }


def _pair_moments(moments: list, k: int, truth: np.ndarray, tracks: list) -> list[dict]:
    """Both methods on robot 1's and robot k's maps at every moment."""
    from polyswarm.benchmarks.gridmerge import Features, match_grids
    from polyswarm.frames.estimate import FrameEstimate
    from polyswarm.frames.mapmatch import MIN_OVERLAP_M2, MatchError, match_maps
    from polyswarm.frames.sighting import (
        MIN_CONTRADICTIONS,
        Room,
        contradictions,
        distinct_places,
        mutual_seen,
    )

    frames = FrameEstimate()
    rows = []
    for t, maps in moments:
        a, b = maps[0], maps[k]
        row: dict = {"t_s": t, "overlap_m2": _true_overlap(a, b, truth)}
        row["overlaps"] = row["overlap_m2"] >= MIN_OVERLAP_M2
        seen_a, seen_b = tracks[0].until(t), tracks[k].until(t)
        rooms = (Room(a), Room(b))  # where each map lets a robot stand

        def contradicts(frame, seen_a=seen_a, seen_b=seen_b, rooms=rooms) -> bool:
            return contradictions(seen_a, seen_b, frame, rooms) >= MIN_CONTRADICTIONS

        t0 = time.perf_counter()
        try:
            m = match_maps(a, b, contradicts, a_paths=seen_a.paths(), b_paths=seen_b.paths())
        except MatchError:
            m = None
        row["ours_s"] = time.perf_counter() - t0
        accepted = m is not None and m.accepted
        row["ours"] = {"accepted": accepted, **_score(m.pose if accepted else None, truth)}
        if m is not None:  # every figure, so thresholds can be studied on the result
            row["ours"]["evidence"] = m.summary()
            row["ours"]["pose"] = [float(v) for v in m.pose]
            row["ours"]["found"] = _score(m.pose, truth)  # the best pose, accepted or not
            for name in ("overlap_m2", "agreeing_wall_m", "agreeing_share", "conflict_share"):
                row["ours"][name] = getattr(m, name)
            row["ours"]["rival_ratio"] = m.rival_ratio
            row["ours"]["margin_wall_m"] = m.margin_wall_m
            row["ours"]["contradicted"] = m.contradicted
            row["ours"]["ambiguous"] = m.ambiguous
            row["ours"]["slight_conflict"] = m.slight_conflict
            # the robots seen where the pose puts them (what commits a frame; robots that
            # explore apart, as these recorded ones did, seldom see each other)
            row["ours"]["seen"] = distinct_places(mutual_seen(seen_a, seen_b, m.pose, (a, b)))
        committed = frames.add(m, row["ours"]["seen"]) if m is not None else frames.pose
        row["committed"] = {"accepted": committed is not None, **_score(committed, truth)}
        for feat in Features:
            t0 = time.perf_counter()
            g = match_grids(a, b, feat)
            row[f"{feat}_s"] = time.perf_counter() - t0
            row[str(feat)] = {"confidence": g.confidence, "scale": g.scale, **_score(g.pose, truth)}
        rows.append(row)
    return rows


def _summary(rows: list[dict], pick: Callable[[dict], dict | None]) -> dict:
    """Over all moments of all pairs: accepted, correct and wrong frames; errors."""
    picked = [(r, pick(r)) for r in rows]
    acc = [(r, p) for r, p in picked if p is not None and p["accepted"]]
    errs = [p["err_m"] for _, p in acc]
    return {
        "moments": len(rows),
        "overlapping_moments": sum(r["overlaps"] for r in rows),
        "accepted": len(acc),
        "accepted_overlapping": sum(r["overlaps"] for r, _ in acc),
        "correct": sum(p["correct"] for _, p in acc),
        "wrong": sum(p["wrong"] for _, p in acc),
        "err_m_median": float(np.median(errs)) if errs else None,
        "err_m_max": float(np.max(errs)) if errs else None,
        "err_deg_max": float(max(p["err_deg"] for _, p in acc)) if acc else None,
    }


def _grid_pick(feat: str, thr: float) -> Callable[[dict], dict]:
    def pick(r: dict) -> dict:
        g = r[feat]
        return {**g, "accepted": g["confidence"] >= thr and g["err_m"] is not None}

    return pick


def _delay(pair_rows: list[dict], pick: Callable[[dict], dict | None]) -> float | None:
    """Simulated seconds from the pair's first overlapping moment to its first accepted
    frame that is not wrong (None: never)."""
    first = next((r["t_s"] for r in pair_rows if r["overlaps"]), None)
    if first is None:
        return None
    for r in pair_rows:
        p = pick(r)
        if p is not None and p["accepted"] and not p["wrong"]:
            return max(0.0, r["t_s"] - first)
    return None


def _one_run(profile: str, world: str, seed: int, robots: int) -> list[dict]:
    """One exploration at scattered starts; every robot's map against robot 1's."""
    from polyswarm.config import Config, with_profile
    from polyswarm.se2 import compose, inverse

    cfg = with_profile(Config(), profile)
    moments, starts, tracks = _snapshots(world, seed, robots, cfg)
    pairs = []
    for k in range(1, robots):
        truth = compose(inverse(np.asarray(starts[0])), np.asarray(starts[k]))
        rows = _pair_moments(moments, k, truth, tracks)
        pairs.append(
            {"profile": profile, "world": world, "seed": seed, "robot": f"r{k + 1}", "rows": rows}
        )
    return pairs


def run(
    worlds: tuple[str, ...],
    seeds: int,
    robots: int = 3,
    profiles: tuple[str, ...] = ("thesis",),
    progress: Callable[[str], None] | None = None,
    jobs: int = 1,
) -> dict:
    """``jobs`` runs side by side in worker processes (match times then share the
    processor: compare them only between results made with one job)."""
    from concurrent.futures import ProcessPoolExecutor

    specs = [(p, w, s, robots) for p in profiles for w in worlds for s in range(seeds)]
    pairs = []
    with ProcessPoolExecutor(jobs) as pool:
        for k, got in enumerate(pool.map(_one_run, *zip(*specs, strict=True))):
            pairs += got
            if progress:
                progress(f"{k + 1} of {len(specs)} runs done")
    all_rows = [r for p in pairs for r in p["rows"]]
    methods: dict[str, Callable[[dict], dict | None]] = {
        "polyswarm_match": lambda r: r["ours"],
        "polyswarm_committed": lambda r: r["committed"],
    }
    for feat in ("akaze", "orb"):
        for thr in GRID_THRESHOLDS:
            methods[f"{feat}_conf{thr}"] = _grid_pick(feat, thr)
    summary = {}
    for name, pick in methods.items():
        s = _summary(all_rows, pick)
        delays = [_delay(p["rows"], pick) for p in pairs]
        overlapping = [
            d for p, d in zip(pairs, delays, strict=True) if any(r["overlaps"] for r in p["rows"])
        ]
        s["pairs_overlapping"] = len(overlapping)
        s["pairs_merged_correctly"] = sum(d is not None for d in overlapping)
        done = [d for d in overlapping if d is not None]
        s["delay_s_median"] = float(np.median(done)) if done else None
        s["delay_s_max"] = float(np.max(done)) if done else None
        # the frame each pair ends with (its last moment), over the pairs that have one
        last = [pick(p["rows"][-1]) for p in pairs if p["rows"]]
        final = [x["err_m"] for x in last if x is not None and x["accepted"]]
        final_deg = [x["err_deg"] for x in last if x is not None and x["accepted"]]
        s["final_frames"] = len(final)
        s["final_err_m_median"] = float(np.median(final)) if final else None
        s["final_err_m_max"] = float(np.max(final)) if final else None
        s["final_err_deg_max"] = float(np.max(final_deg)) if final_deg else None
        summary[name] = s
    ours_s = [r["ours_s"] for r in all_rows]
    return {
        "profiles": list(profiles),
        "worlds": list(worlds),
        "seeds": seeds,
        "jobs": jobs,
        "robots": robots,
        "snapshot_s": SNAPSHOT_S,
        "methods": summary,
        "match_s_median": float(np.median(ours_s)) if ours_s else None,
        "match_s_p95": float(np.percentile(ours_s, 95)) if ours_s else None,
        "akaze_s_median": float(np.median([r["akaze_s"] for r in all_rows])) if all_rows else None,
        "pairs": pairs,
    }
