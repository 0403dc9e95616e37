"""``polyswarm bench faults``: the fault a real deployment meets, from outside.

Each run is a ``polyswarm launch`` (every part its own process) in which one process,
an agent, the simulator or the coordinator, drawn by the run's seed, is killed with
SIGKILL by its process id (``logs/pids.json``) at a random moment of the mission (read
from the simulator's own state file, so that it falls inside the run however fast the
machine is), as the kernel's out-of-memory killer or a crash would: not through
launch's fault injection.
``launch`` restarts it. Measured per run: whether the exploration still reached 99 %
(t99), the restarts, and what any robot shared that is missing from the coordinator's
final merged map (``missing_m2``), or that a robot no longer holds (``dropped_m2``).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

# simulated seconds into the mission: the kill's window (3-robot office and maze runs
# reach 99 % after 75-180 s; a wall-clock window of 5-40 s missed 3 of 10 runs)
KILL_AT_SIM_S = (5.0, 60.0)
POLL_S = 0.05  # wall seconds between reads of the simulator's state
MISSING_SHARE = 1e-3  # a robot's shared space missing from the merge beyond this: lost


def lost_space(out: Path) -> dict[str, dict[str, float]]:
    """Per robot: explored space it shared (the coordinator's copy of its map) that is
    not in the final merged map (``missing_m2``), and that the robot's own persisted map
    no longer holds (``dropped_m2``); with the shared area (``shared_m2``)."""
    import shapely

    from agents import persist

    state = out / "state"
    merged, robots = persist.load_coordinator(state)  # snapshots plus journals
    merged_region = merged.explored_region() if merged is not None else shapely.Polygon()
    res = {}
    for rid, pmap in sorted(robots.items()):
        received = pmap.explored_region()
        own = persist.load_agent(state, rid)
        own_region = own[0].explored_region() if own is not None else shapely.Polygon()
        res[rid] = {
            "shared_m2": float(received.area),
            "missing_m2": float(shapely.difference(received, merged_region).area),
            "dropped_m2": float(shapely.difference(received, own_region).area),
        }
    return res


def _sim_time_s(state: Path, physics_hz: float) -> float:
    """The simulated time the simulator last saved (0 before its first save)."""
    try:
        return json.loads((state / "sim.json").read_text())["steps"] / physics_hz
    except (OSError, ValueError, KeyError):  # not written yet, or being replaced
        return 0.0


def _kill_later(
    out: Path, name: str, at_sim_s: float, physics_hz: float, seen: dict, stop: threading.Event
) -> None:
    """SIGKILL process ``name`` of the launch writing to ``out`` once its mission reaches
    ``at_sim_s`` simulated seconds."""
    while _sim_time_s(out / "state", physics_hz) < at_sim_s:
        if stop.wait(POLL_S):
            seen["error"] = "the run ended first"
            return
    try:
        pid = json.loads((out / "logs" / "pids.json").read_text())[name]
        os.kill(pid, signal.SIGKILL)
        seen.update(pid=pid, at_sim_s=_sim_time_s(out / "state", physics_hz))
    except (OSError, KeyError, ValueError) as e:  # the run ended first, or no such child
        seen["error"] = str(e)


def one_run(world: str, robots: int, seed: int, wall_limit_s: float, out: Path) -> dict:
    from polyswarm.config import Config
    from polyswarm.runners.launch import LaunchOptions, launch

    rng = np.random.default_rng([seed, len(world)])
    victims = ["sim", "coordinator", *(f"r{k + 1}" for k in range(robots))]
    victim = victims[int(rng.integers(len(victims)))]
    at_s = float(rng.uniform(*KILL_AT_SIM_S))
    seen: dict = {}
    stop = threading.Event()
    hz = Config().sim.physics_hz  # launch runs the default configuration
    killer = threading.Thread(
        target=_kill_later, args=(out, victim, at_s, hz, seen, stop), daemon=True
    )
    killer.start()
    t0 = time.monotonic()
    opts = LaunchOptions(
        world=world,
        robots=robots,
        seed=seed,
        speed=0.0,
        stop_coverage=0.99,
        wall_limit_s=wall_limit_s,
        out=out,
    )
    try:
        m = launch(opts).metrics
    finally:
        stop.set()
        killer.join(timeout=2)
    lost = lost_space(out)
    return {
        "world": world,
        "seed": seed,
        "victim": victim,
        "killed": "pid" in seen,
        "kill_at_sim_s": seen.get("at_sim_s", at_s),
        "t99_s": m["t99_s"],
        "final_coverage": m["final_coverage"],
        "restarts": m["restarts"],
        "crashed_processes": m["crashed_processes"],
        "stopped_because": m["stopped_because"],
        "wall_time_s": time.monotonic() - t0,
        "missing_m2_max": max((v["missing_m2"] for v in lost.values()), default=0.0),
        "dropped_m2_max": max((v["dropped_m2"] for v in lost.values()), default=0.0),
        "lost_share_max": max(
            (max(v["missing_m2"], v["dropped_m2"]) / max(v["shared_m2"], 1e-9))
            for v in lost.values()
        )
        if lost
        else 0.0,
        "out": str(out),
    }


def run(
    worlds: tuple[str, ...],
    seeds: int,
    robots: int,
    wall_limit_s: float,
    out_root: Path,
    progress: Callable[[str], None] | None = None,
) -> dict:
    rows = []
    for world in worlds:
        for seed in range(seeds):
            if progress:
                progress(f"{world}, seed {seed}")
            out = out_root / f"{world.replace(':', '_')}-{seed}"
            if out.exists():  # a run folder resumes persisted state: start afresh
                shutil.rmtree(out)
            rows.append(one_run(world, robots, seed, wall_limit_s, out))
    ok = [
        r["killed"] and r["t99_s"] is not None and r["lost_share_max"] <= MISSING_SHARE
        for r in rows
    ]
    return {
        "robots": robots,
        "runs": rows,
        "runs_ok": int(sum(ok)),
        "runs_total": len(rows),
        "reached_99": int(sum(r["t99_s"] is not None for r in rows)),
        "killed": int(sum(r["killed"] for r in rows)),
        "lost_share_max": max((r["lost_share_max"] for r in rows), default=0.0),
    }
