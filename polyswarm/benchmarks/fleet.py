"""``polyswarm bench fleet``: many robots on hosts of their own, against one network stack.

For each robot count, two ``polyswarm launch`` runs side by side on the same world,
seed and wall-clock limit: every process on one network stack (clients of one router
on loopback), and every robot and coordinator in a network namespace of its own
(``launch --netns``: a router per host, a mesh over one bridge). Measured per run:
the coordinator's cycle p95 (wall and processor time), the bytes each robot sent
(median and largest, and per simulated second: on a busy machine the two runs get as
far as it lets them), coverage reached, and whether every map the coordinator holds
is the robot's own at the end (``--netns``). The ratio of bytes per robot per simulated
second, namespaces over one stack, is the cost of the mesh. Needs root for ``--netns``.
"""

from __future__ import annotations

import statistics
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

COUNTS = (10, 25)
WORLD = "data:nav2-warehouse"  # a floor with room for 25 robots
WALL_LIMIT_S = 300.0


def _row(m: dict, netns: bool) -> dict:
    sent = list(m["bytes_sent_per_robot"].values())
    agree = m.get("maps_agree", {})
    return {
        "netns": netns,
        "robots": m["robots"],
        "coordinator_cycle_p95_ms": m["coordinator_cycle_p95_ms"],
        "coordinator_cycle_cpu_p95_ms": m["coordinator_cycle_cpu_p95_ms"],
        "bytes_per_robot_median": statistics.median(sent) if sent else 0,
        "bytes_per_robot_max": max(sent) if sent else 0,
        # the runs get as far as the machine lets them in the same wall time
        "bytes_per_robot_per_sim_s": (
            statistics.median(sent) / m["sim_time_s"] if sent and m["sim_time_s"] else 0.0
        ),
        "final_coverage": m["final_coverage"],
        "sim_time_s": m["sim_time_s"],
        "crashed_processes": m["crashed_processes"],
        "maps_agree": all(v["agree"] for v in agree.values()) if agree else None,
    }


def run(
    counts=COUNTS,
    world: str = WORLD,
    wall_limit_s: float = WALL_LIMIT_S,
    out: Path | None = None,
    seed: int = 0,
    on_run: Callable[[int, bool], None] | None = None,
) -> dict:
    from polyswarm.runners.launch import LaunchOptions, launch

    out = out or Path(tempfile.mkdtemp(prefix="polyswarm-bench-fleet-"))
    rows = []
    for n in counts:
        for netns in (False, True):
            if on_run:
                on_run(n, netns)
            opts = LaunchOptions(
                world=world,
                robots=n,
                seed=seed,
                speed=0.0,
                wall_limit_s=wall_limit_s,
                out=out / f"{n}-{'netns' if netns else 'loopback'}",
                netns=netns,
            )
            rows.append(_row(launch(opts).metrics, netns))
    ratios = {}
    for n in counts:
        one = next(r for r in rows if r["robots"] == n and not r["netns"])
        mesh = next(r for r in rows if r["robots"] == n and r["netns"])
        if one["bytes_per_robot_per_sim_s"]:
            ratios[str(n)] = mesh["bytes_per_robot_per_sim_s"] / one["bytes_per_robot_per_sim_s"]
    return {
        "world": world,
        "seed": seed,
        "wall_limit_s": wall_limit_s,
        "runs": rows,
        "bytes_per_robot_ratio_netns_vs_loopback": ratios,
        "out": str(out),
    }


def _launch(out: Path, world: str, seed: int, faults: str, wall_limit_s: float, **kw) -> dict:
    from polyswarm.runners.launch import Fault, LaunchOptions, launch

    opts = LaunchOptions(
        world=world,
        robots=3,
        seed=seed,
        speed=0.0,
        wall_limit_s=wall_limit_s,
        out=out,
        netns=True,
        faults=Fault.parse_many(faults),
        **kw,
    )
    return launch(opts).metrics


CUTS = "cut:r1@30,restore:r1@90,cut:r2@50,restore:r2@170"  # r1 out for 60 s, r2 for 120 s


def cuts(
    worlds=("office", "data:nav2-warehouse"),
    seeds=(0, 1, 2),
    wall_limit_s: float = 600.0,
    out: Path | None = None,
    on_run: Callable[[str, int], None] | None = None,
) -> dict:
    """3 robots in namespaces, r1 cut off for 60 s and r2 for 120 s (``CUTS``): coverage,
    t99, the keyframes each made while cut off, maps agreeing at the end."""
    out = out or Path(tempfile.mkdtemp(prefix="polyswarm-bench-cuts-"))
    rows = []
    for world in worlds:
        for seed in seeds:
            if on_run:
                on_run(world, seed)
            m = _launch(out / f"{world.replace(':', '_')}-{seed}", world, seed, CUTS, wall_limit_s)
            rows.append(
                {
                    "world": world,
                    "seed": seed,
                    "final_coverage": m["final_coverage"],
                    "t99_s": m["t99_s"],
                    "map_iou": m["map_iou"],
                    "keyframes_while_cut": {  # None: its return was never seen
                        o["robot"]: None
                        if o["keyframes_at_rejoin"] is None
                        else o["keyframes_at_rejoin"] - o["keyframes_at_cut"]
                        for o in m["link_outages"]
                    },
                    "maps_agree": all(v["agree"] for v in m["maps_agree"].values()),
                    "crashed_processes": m["crashed_processes"],
                }
            )
    return {
        "faults": CUTS,
        "runs": rows,
        "reached_99_all": all(r["final_coverage"] >= 0.99 for r in rows),
        "maps_agree_all": all(r["maps_agree"] for r in rows),
        "out": str(out),
    }


def takeovers(
    runs: int = 10,
    world: str = "office",
    wall_limit_s: float = 400.0,
    out: Path | None = None,
    on_run: Callable[[int, float], None] | None = None,
) -> dict:
    """3 robots and 2 coordinators in namespaces; the active coordinator's host lost
    (killed and cut off) at a random moment (seeded, 20-80 simulated seconds): the
    wall seconds until the standby's first status, and whether the mission ended."""
    import random

    out = out or Path(tempfile.mkdtemp(prefix="polyswarm-bench-takeover-"))
    rng = random.Random(0)
    rows = []
    for k in range(runs):
        at = round(rng.uniform(20.0, 80.0), 1)
        if on_run:
            on_run(k, at)
        faults = f"kill:coordinator@{at},cut:coordinator@{at}"
        m = _launch(out / f"run-{k}", world, k, faults, wall_limit_s, coordinators=2)
        rows.append(
            {
                "seed": k,
                "lost_at_s": at,
                "takeover_s": m["takeover_s"][0] if m["takeover_s"] else None,
                "mission_state": m["mission_state"],
                "final_coverage": m["final_coverage"],
                "leaders": m["leaders"],
            }
        )
    times = [r["takeover_s"] for r in rows if r["takeover_s"] is not None]
    return {
        "world": world,
        "runs": rows,
        "takeover_p95_s": float(np.percentile(times, 95)) if times else None,
        "takeover_max_s": max(times) if times else None,
        "took_over": len(times),
        "missions_done": sum(r["mission_state"] == "done" for r in rows),
        "out": str(out),
    }
