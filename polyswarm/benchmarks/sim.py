"""``polyswarm bench sim``: ray casting throughput, real-time factor, memory."""

from __future__ import annotations

import dataclasses
import resource
import time

import numpy as np

from polyswarm.config import Config
from sim import Simulation, load_world
from sim.wander import Wander

BLOCK_S = 10.0  # simulated seconds per timing block (the median of blocks is reported)


def scans_per_second(world, cfg, robots: int, batches: int = 60) -> float:
    with Simulation(world, cfg.sim, robots) as sim:
        sim.scan()  # warm up
        times = []
        for _ in range(batches):
            t0 = time.perf_counter()
            sim.scan()
            times.append(time.perf_counter() - t0)
    return robots / float(np.median(times))


def real_time_factors(world, cfg, robots: int = 3, blocks: int = 6) -> dict:
    """Full stepping against ray casting alone, measured alternately in one run."""
    with Simulation(world, cfg.sim, robots) as sim:
        ctl = [Wander(k) for k in range(robots)]
        steps_per_block = round(BLOCK_S / sim.dt)
        scans_per_block = round(BLOCK_S * cfg.sim.lidar.rate_hz)
        step_rtf, ray_rtf = [], []
        for _ in range(blocks):
            spent = 0.0
            for _ in range(steps_per_block):
                t0 = time.perf_counter()
                events = sim.step()
                spent += time.perf_counter() - t0
                for ev in events:  # the controller is not part of the simulator's cost
                    sim.set_cmd(ev.robot, *ctl[ev.robot].command(ev.scan))
            step_rtf.append(BLOCK_S / spent)
            t0 = time.perf_counter()
            for _ in range(scans_per_block):
                sim.scan()
            ray_rtf.append(BLOCK_S / (time.perf_counter() - t0))
        collisions = sum(r.wall_collisions + r.robot_collisions for r in sim.robots)
    full, ray = float(np.median(step_rtf)), float(np.median(ray_rtf))
    return {
        "real_time_factor": full,
        "raycast_only_real_time_factor": ray,
        "non_raycast_fraction": 1.0 - full / ray,
        "contacts_while_wandering": collisions,
    }


def run(world_name: str = "data:maze") -> dict:
    cfg = Config()
    world = load_world(world_name)
    sps = {str(n): scans_per_second(world, cfg, n) for n in (1, 3, 10)}
    rtf = real_time_factors(world, cfg, 3)
    # the same with pybullet's ray casting on the caller's thread only, for comparison
    one = dataclasses.replace(cfg.sim, raycast_threads=1)
    rtf1 = real_time_factors(world, dataclasses.replace(cfg, sim=one), 3)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux
    return {
        "world": world.name,
        "beams": cfg.sim.lidar.beams,
        "physics_hz": cfg.sim.physics_hz,
        "scans_per_s": sps,
        "real_time_factor_3_robots": rtf["real_time_factor"],
        "raycast_only_real_time_factor_3_robots": rtf["raycast_only_real_time_factor"],
        "non_raycast_fraction_3_robots": rtf["non_raycast_fraction"],
        "raycast_threads": cfg.sim.raycast_threads,
        "real_time_factor_3_robots_one_raycast_thread": rtf1["real_time_factor"],
        "peak_memory_mb": peak,
    }
