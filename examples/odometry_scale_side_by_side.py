"""PolySLAM with and without learning the odometry's distance scale, side by side.

Every run is made twice, ``slam.learn_odometry_scale`` off and on, on two processes:

    # simulated thesis worlds along their coverage routes: worlds, profiles, seeds 0..n-1
    python examples/odometry_scale_side_by_side.py worlds runs.jsonl \
        loop,cross,zigzag,maze thesis,thesis-noisy-odometry,turtlebot3 3
    # the shared logs: real wheel odometry where a log has it, synthetic noise (seed 0)
    python examples/odometry_scale_side_by_side.py logs runs.jsonl '*.log.gz'
    # medians and worst cases of the runs, per world/log and profile, into a result file
    python examples/odometry_scale_side_by_side.py summary runs.jsonl \
        docs/results/odometry-scale.json [CODE_VERSION of the runs; default: git describe]

Each line of the runs file is one run: what it was and its ``polyswarm.runners.slam``
metrics (ATE of the optimised and the online trajectory, map IoU against the world).
"""

from __future__ import annotations

import itertools
import json
import multiprocessing as mp
import statistics
import sys
import time
from pathlib import Path

KEYS = (
    "ate_rmse_m",
    "ate_rmse_online_m",
    "map_iou",
    "odometry_ate_rmse_m",
    "loops_closed",
    "degenerate_keyframes",
    "keyframe_p95_ms",
)


def _run(spec) -> dict:
    kind, target, variant, seed, learn = spec
    import logging

    logging.disable(logging.WARNING)
    from polyswarm.config import Config, with_overrides, with_profile
    from polyswarm.runners.slam import OdometrySource, metrics, run_log, run_world

    t0 = time.time()
    try:
        if kind == "world":  # variant: the robot profile
            cfg = with_profile(Config(), variant)
            cfg = with_overrides(cfg, {"slam": {"learn_odometry_scale": learn}})
            run = run_world(target, cfg, seed=seed)
        else:  # variant: the odometry source
            cfg = with_overrides(Config(), {"slam": {"learn_odometry_scale": learn}})
            run = run_log(target, cfg, seed=seed, odometry=OdometrySource(variant))
    except Exception as e:  # a log without real odometry: recorded, not fatal
        return {"spec": spec, "error": repr(e)}
    m = metrics(run)
    out = {k: m.get(k) for k in KEYS}
    out["scale"] = run.slam.odometry_scale.raw
    return {"spec": spec, **out, "s": round(time.time() - t0)}


def _specs(argv: list[str]) -> list[tuple]:
    if argv[0] == "worlds":
        worlds, profiles, seeds = argv[2].split(","), argv[3].split(","), range(int(argv[4]))
        return [
            ("world", f"data:{w}", p, s, learn)
            for w, p, s in itertools.product(worlds, profiles, seeds)
            for learn in (False, True)
        ]
    from polyswarm.data import log_paths

    return [
        ("log", str(log), odo, 0, learn)
        for log in log_paths()
        if log.match(argv[2])
        for odo in ("log", "noise")
        for learn in (False, True)
    ]


def summary(runs_path: str, out_path: str, version: str = "") -> None:
    rows = [json.loads(line) for line in Path(runs_path).read_text().splitlines()]
    groups: dict = {}
    for r in rows:
        if "error" in r:
            continue
        _, target, variant, seed, learn = r["spec"]
        name = Path(target).name.split("-corrected")[0] if "/" in target else target
        g = groups.setdefault(f"{name} {variant}", {"off": {}, "on": {}})
        g["on" if learn else "off"][seed] = r
    out: dict = {}
    for key, g in sorted(groups.items()):
        seeds = sorted(set(g["off"]) & set(g["on"]))
        entry: dict = {"seeds": seeds}
        for side in ("off", "on"):
            runs = [g[side][s] for s in seeds]
            for k in ("ate_rmse_m", "ate_rmse_online_m", "map_iou"):
                vals = [r[k] for r in runs if r.get(k) is not None]
                if not vals:
                    continue
                worst = min(vals) if k == "map_iou" else max(vals)
                entry[f"{k}_{side}"] = {"median": statistics.median(vals), "worst": worst}
        entry["scale_learnt"] = [g["on"][s]["scale"] for s in seeds]
        out[key] = entry
    from polyswarm.benchmarks.results import machine_meta

    meta = machine_meta() | {"command": " ".join(["python", *sys.argv]), "runs": runs_path}
    if version:  # the runs were made before this summary, at this code
        meta["code_version"] = version
    Path(out_path).write_text(json.dumps({"groups": out, "meta": meta}, indent=1) + "\n")


def main(argv: list[str]) -> None:
    if argv[0] == "summary":
        summary(*argv[1:4])
        return
    with mp.Pool(2) as pool, open(argv[1], "a") as f:
        for res in pool.imap_unordered(_run, _specs(argv)):
            f.write(json.dumps(res) + "\n")
            f.flush()


if __name__ == "__main__":
    main(sys.argv[1:])
