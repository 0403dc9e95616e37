"""``polyswarm bench load``: many robots against one coordinator, over time.

A ``polyswarm launch`` with N robots (every part its own process, Zenoh on loopback)
runs for a wall-clock duration (the soak). Measured:

* ``coordinator_cycle_p95_ms``: from the coordinator's status messages (merge, frontiers,
  costs and assignment of each cycle, with the merges since the previous one), wall
  time; ``coordinator_cycle_cpu_p95_ms`` the processor time of the same cycles (the
  difference is time the coordinator waited for the processor);
* ``messages_lost``: robot map versions the coordinator never received, from the state
  both sides persist at shutdown (each missing version is a delta neither delivered
  nor recovered by a resync);
* ``robot_map_gaps``, ``robot_map_fetches``, ``robot_map_fetch_bytes``: losses in
  transit as they happened (robot map updates that did not apply: lost, late, or
  replayed otherwise), and the whole-map fetches that healed them, with their bytes;
  ``messages_lost`` looks only at the end, after the fetches;
* ``memory_growth_fraction``: the coordinator's resident memory at the end against
  its value after the first tenth of the run (the map grows, so some growth is data);
  ``memory_growth_fraction_second_half`` the same from the middle of the run, when a
  30-minute soak has long finished mapping its world (a leak would still show there).

On this 2-core machine ten agents with PolySLAM slow the lockstep simulation down;
the figures are those of the coordinator under that load. The simulator and agents run
at a lower priority (``robots_nice``): they stand for the robots' own computers, and
the coordinator for the fleet's machine; ``robots_nice=0`` measures the coordinator
competing with all of them for two cores.
"""

from __future__ import annotations

import tempfile
from pathlib import Path


def run(
    robots: int,
    world: str,
    duration_s: float,
    out: Path | None,
    seed: int = 0,
    robots_nice: int = 5,
) -> dict:
    from agents import persist
    from polyswarm.runners.launch import LaunchOptions, launch

    out = out or Path(tempfile.mkdtemp(prefix="polyswarm-bench-load-"))
    opts = LaunchOptions(
        world=world,
        robots=robots,
        seed=seed,
        speed=0.0,
        wall_limit_s=duration_s,
        out=out,
        robots_nice=robots_nice,
    )
    m = launch(opts).metrics
    state = out / "state"
    lost = 0
    per_robot = {}
    _, received = persist.load_coordinator(state)  # snapshots plus journals, both sides
    for k in range(robots):
        rid = f"r{k + 1}"
        own = persist.load_agent(state, rid)
        sent_v = own[0].version if own is not None else 0
        got_v = received[rid].version if rid in received else 0
        per_robot[rid] = {"sent_version": sent_v, "received_version": got_v}
        lost += max(0, sent_v - got_v)
    rss = m["coordinator_rss_mb_over_time"]
    growth = growth_late = None
    if len(rss) >= 3:
        base = rss[max(1, len(rss) // 10)][1]
        growth = (rss[-1][1] - base) / base
        half = rss[len(rss) // 2][1]  # by then a soak long enough has mapped its world
        growth_late = (rss[-1][1] - half) / half
    return {
        "robots": robots,
        "world": world,
        "wall_time_s": m["wall_time_s"],
        "sim_time_s": m["sim_time_s"],
        "messages_lost": lost,
        "robot_map_gaps": m["robot_map_gaps"],
        "robot_map_fetches": m["robot_map_fetches"],
        "robot_map_fetch_bytes": m["robot_map_fetch_bytes"],
        "coordinator_cycle_p95_ms": m["coordinator_cycle_p95_ms"],
        "coordinator_cycle_cpu_p95_ms": m["coordinator_cycle_cpu_p95_ms"],
        "robots_nice": robots_nice,
        "memory_growth_fraction": growth,
        "memory_growth_fraction_second_half": growth_late,
        "coordinator_rss_mb_first_last": [rss[0][1], rss[-1][1]] if rss else None,
        "final_coverage": m["final_coverage"],
        "crashed_processes": m["crashed_processes"],
        "per_robot": per_robot,
        "out": str(out),
    }
