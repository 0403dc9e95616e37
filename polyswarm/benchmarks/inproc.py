"""A whole exploration in one process: simulator, robot agents and coordinator wired
directly (no Zenoh), for benchmarks that measure the parts rather than the transport.

Deltas still pass through the wire codec, so their sizes are the sizes on the wire.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from polyswarm.config import Config, RobotEntry
from polyswarm.errors import MapError
from polyswarm.evaluation.coverage import coverage_tolerance, reachable_free
from polyswarm.polymap import MapDelta, MergeOp
from polyswarm.slam.follow import CorrectionOp
from polyswarm.slam.scan import LaserScan

# (robot id, simulated time s, scan, SLAM pose (x, y, theta), the robot's map delta, the
# same change as the merge that made it or None, and the correction before it or None)
KeyframeHook = Callable[
    [str, float, LaserScan, np.ndarray, MapDelta, MergeOp | None, CorrectionOp | None], None
]


@dataclass
class InProcessRun:
    coordinator: object  # agents.coordinator.Coordinator
    agents: list
    sim_time_s: float
    delta_bytes: int
    coverage: list[tuple[float, float]]  # (simulated s, fraction of the free space)


def _agent_event(ev, sim, agents, coord, on_keyframe, on_pose) -> int:
    """One scan event: the agent's step, its commands to the simulator, its map update,
    pose and status to the coordinator and the other agents; the bytes it sent."""
    from protocols.chunks import MAP_KIND_OF
    from protocols.mapcodec import encode_updates
    from protocols.messages import Odometry

    sent = 0
    a = agents[ev.robot]
    a.on_odom(sim.time, Odometry(*ev.odom))
    out = a.on_scan(sim.time, ev.scan)  # now: the end of its sweep
    if out.cmd:
        sim.set_cmd(ev.robot, *out.cmd)
    if out.delta is not None:  # what the agent sends: the merge or the cells
        for what, _, _, wire in encode_updates(out.delta, out.op, out.correction):
            sent += len(wire)
            coord.on_robot_update(a.id, sim.time, MAP_KIND_OF[what], wire)
        if on_keyframe is not None:
            on_keyframe(
                a.id,
                sim.time,
                ev.scan,
                a.pose.copy(),
                out.delta,
                out.op,
                out.correction,
            )
    if out.pose is not None:
        if on_pose is not None:
            on_pose(ev.robot, sim.time, out.pose)
        coord.on_pose(a.id, sim.time, out.pose)
        for b in agents:
            b.on_peer_pose(a.id, sim.time, out.pose)
    if out.status is not None:
        coord.on_status(a.id, sim.time, out.status)
    return sent


def _coordinate(coord, agents, now_s: float) -> None:
    """The coordinator's turn: replays taken in, merged deltas flushed, a cycle when due
    (assignments to the agents), the merged map to every agent."""
    for rid, got in coord.take_in():  # replayed on the pool's processes
        if isinstance(got, MapError):  # the robot's map, as a resync fetches it
            coord.on_robot_map(rid, agents[int(rid[1:]) - 1].slam.map)
    deltas = [coord.flush()] if coord.flush_due() else []
    if coord.due():
        o = coord.cycle()
        deltas.append(o.merged_delta)
        for rid, asg in o.assignments.items():
            agents[int(rid[1:]) - 1].on_assignment(asg, now_s)
    for merged in filter(None, deltas):
        for b in agents:
            if b.merged is None:
                b.on_merged_map(coord.merged)
            else:
                b.on_merged_delta(merged)


def explore_in_process(
    world_name: str,
    robots: int,
    sim_s: float,
    seed: int = 0,
    cfg: Config | None = None,
    on_keyframe: KeyframeHook | None = None,
    stop_coverage: float = 1.01,
    on_step: Callable[[object, list, object], None] | None = None,
    start_poses: list | None = None,
    on_pose: Callable[[int, float, object], None] | None = None,
    sightings: bool | None = None,
    replay_workers: int = 0,
    merge_process: bool = False,
) -> InProcessRun:
    """``on_step(sim, agents, coordinator)`` is called after every simulation step with
    scans (for instrumentation); ``on_pose(robot index, time s, Pose)`` with every pose
    an agent sends. ``start_poses`` (x m, y m, theta rad) per robot: the robots' true
    starts, also given to the coordinator (default: side by side at the world's start).
    ``replay_workers`` processes replay the robots' merges for the coordinator
    (``agents.replay``); with none it replays them itself, and a run is the same each time.
    ``merge_process``: merge on a process of its own (``agents.merger``)."""
    import shapely

    from agents.coordinator import Coordinator
    from agents.merger import MergeProcess
    from agents.replay import ReplayPool
    from agents.robot import RobotAgent
    from protocols.messages import MissionState
    from sim import Simulation, load_world, spread_start_poses

    cfg = cfg or Config()
    world = load_world(world_name, seed=seed)
    starts = start_poses or spread_start_poses(world, robots, cfg.sim.robot.radius_m)
    cfg = dataclasses.replace(
        cfg,
        sim=dataclasses.replace(cfg.sim, seed=seed),
        robots=tuple(RobotEntry(f"r{k + 1}", s) for k, s in enumerate(starts)),
    )
    agents = [RobotAgent(f"r{k + 1}", cfg, starts[k]) for k in range(robots)]
    for a in agents:
        a.sightings = sightings
    coord = Coordinator(cfg, {a.id: a.start_pose for a in agents})
    pool = coord.use_pool(ReplayPool(replay_workers)) if replay_workers else None
    merger = coord.use_merger(MergeProcess(coord.merged, cfg.nav)) if merge_process else None
    for a in agents:
        coord.on_alive(a.id, True)
    delta_bytes = 0
    coverage: list[tuple[float, float]] = []
    lid = cfg.sim.lidar
    res = world.grid.resolution if world.grid is not None else 0.0
    tol = coverage_tolerance(lid.noise_sigma_m, lid.noise_sigma_per_m, res)
    free = reachable_free(world.free, cfg.sim.robot.radius_m, starts, tol)
    next_sample = 0.0
    with (
        Simulation(world, cfg.sim, robots, start_poses=starts) as sim,
        _closing(pool),
        _closing(merger),
    ):
        while sim.time < sim_s:
            events = sim.step()
            for ev in events:
                delta_bytes += _agent_event(ev, sim, agents, coord, on_keyframe, on_pose)
            if not events:
                continue
            if on_step is not None:
                on_step(sim, agents, coord)
            _coordinate(coord, agents, sim.time)
            if sim.time >= next_sample:
                next_sample += 1.0
                region = coord.merged.explored_region()
                cov = shapely.intersection(region, free).area / free.area
                coverage.append((sim.time, cov))
                if cov >= stop_coverage or coord.state == MissionState.DONE:
                    break
        coord.drain()  # every replay counted
    return InProcessRun(coord, agents, sim.time, delta_bytes, coverage)


@contextmanager
def _closing(pool):
    try:
        yield pool
    finally:
        if pool is not None:
            pool.close()
