"""``polyswarm bench load``: many robots against one coordinator, over time.

A ``polyswarm launch`` with N robots (every part its own process, Zenoh on loopback)
runs for a wall-clock duration (the soak), on after the building is mapped. Measured:

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
* ``memory_growth_fraction``, ``memory_growth_fraction_second_half``: the coordinator's
  resident memory, see ``memory_growth``; ``agent_memory_growth_second_half_max`` the
  worst agent's, and ``agent_kb_per_keyframe_*`` an agent's memory per keyframe it made;
  ``memory`` has every process's figures.

On this 2-core machine ten agents with PolySLAM slow the lockstep simulation down;
the figures are those of the coordinator under that load. The simulator and agents run
at a lower priority (``robots_nice``): they stand for the robots' own computers, and
the coordinator for the fleet's machine; ``robots_nice=0`` measures the coordinator
competing with all of them for two cores.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

MIN_KEYFRAME_SPAN = 20  # keyframes a process must have added to fit its memory per keyframe


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
        stop_when_done=False,  # the whole soak, mapping and then holding the map
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
    memory = {name: memory_growth(rows) for name, rows in m["rss_mb_over_time"].items()}
    agents_mem = [
        v for k, v in memory.items() if k in per_robot and v["growth_second_half"] is not None
    ]
    coord = memory.get("coordinator", memory_growth([]))
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
        "memory_growth_fraction": coord["growth"],
        "memory_growth_fraction_second_half": coord["growth_second_half"],
        "coordinator_rss_mb_first_last": coord["mb_first_last"],
        # the agents' worst: growth over the second half, and memory per keyframe
        "agent_memory_growth_second_half_max": max(
            (v["growth_second_half"] for v in agents_mem), default=None
        ),
        "agent_kb_per_keyframe_median": _median(v["kb_per_keyframe"] for v in agents_mem),
        "agent_kb_per_keyframe_max": max(
            (v["kb_per_keyframe"] for v in agents_mem if v["kb_per_keyframe"] is not None),
            default=None,
        ),
        "agent_rss_mb_last_max": max((v["mb_first_last"][1] for v in agents_mem), default=None),
        "memory": memory,
        "final_coverage": m["final_coverage"],
        "crashed_processes": m["crashed_processes"],
        "per_robot": per_robot,
        "out": str(out),
    }


def memory_growth(rows: list) -> dict:
    """Growth of one process's resident memory from rows of (wall s, MB, keyframes).

    ``growth``: the end against the value after the first tenth of the run (the map
    grows, so some growth is data); ``growth_second_half``: the same from the middle,
    when a 30-minute soak has long finished mapping its world (a leak would still show
    there); ``kb_per_keyframe``: the slope of memory over the keyframes a robot made
    (least squares, from its first keyframe on: the imports before it are not data),
    None for fewer than ``MIN_KEYFRAME_SPAN`` keyframes."""
    out = {"mb_first_last": None, "growth": None, "growth_second_half": None}
    out["kb_per_keyframe"] = None
    if len(rows) < 3:
        return out
    mb = np.array([r[1] for r in rows], dtype=float)
    kf = np.array([r[2] for r in rows], dtype=float)
    base, half = mb[max(1, len(mb) // 10)], mb[len(mb) // 2]
    out["mb_first_last"] = [float(mb[0]), float(mb[-1])]
    out["growth"] = float((mb[-1] - base) / base)
    out["growth_second_half"] = float((mb[-1] - half) / half)
    mapping = kf > 0
    if mapping.any() and kf.max() - kf[mapping].min() >= MIN_KEYFRAME_SPAN:
        slope = np.polyfit(kf[mapping], mb[mapping], 1)[0]
        out["kb_per_keyframe"] = float(slope * 1024.0)
    return out


def _median(values) -> float | None:
    v = [x for x in values if x is not None]
    return float(np.median(v)) if v else None
