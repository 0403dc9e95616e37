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
