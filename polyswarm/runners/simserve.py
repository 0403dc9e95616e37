"""``polyswarm sim --serve``: the simulator on Zenoh.

Steps the pybullet world at ``speed`` simulated seconds per wall second; at every
lidar tick publishes each robot's odometry and scan (stamped with simulated time), the
clock, and the ground truth on its own key (for metrics only). Velocity commands are
applied as they arrive; a robot with no command for ``CMD_TIMEOUT_S`` stops.

Agents acknowledge scans in their commands (``CmdVel.ack``). The simulator never runs
more than ``max_lag_s`` of simulated time ahead of a live agent's last acknowledged
scan: on a busy machine the simulation slows down instead of robots driving blind.
Before the first step it waits until every robot's agent (and the coordinator, when
asked) holds a liveliness token.

With ``persist.dir`` set, the simulator's state (time, robots' true poses, odometry and
noise generators) is written there after every lidar tick (``sim.json``), and a
simulator started on it goes on from there, one scan later: a killed simulator that is
started again (``polyswarm launch`` does) continues the same mission; its robots are
where they were.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import threading
import time
from pathlib import Path

import numpy as np

from agents.session import Bus, SessionSpec, is_alive_change, open_session
from polyswarm.config import Config
from polyswarm.errors import SimulationError
from protocols.keys import SwarmKeys
from protocols.messages import Clock, CmdVel, Odometry, Scan, Truth
from sim import Simulation, World

log = logging.getLogger(__name__)

STATE_FILE = "sim.json"  # in persist.dir
CMD_TIMEOUT_S = 0.5  # simulated seconds without a command: the robot stops
ACK_TIMEOUT_S = 1.0  # wall seconds: a scan never acknowledged this long was lost
STALL_WARN_S = 5.0  # wall seconds waiting for an agent before a warning


def serve(
    cfg: Config,
    world: World,
    session_spec: SessionSpec,
    stop: threading.Event,
    speed: float | None = None,
    max_lag_s: float = 0.25,
    wait_for: tuple[str, ...] = ("agents",),
    duration_s: float = math.inf,
    gui: bool = False,
    robot_links: dict[str, SessionSpec] | None = None,
) -> Simulation:
    """Run until ``stop`` is set or ``duration_s`` simulated seconds have passed.
    ``robot_links``: a robot's own session (its sensors on board: a link of its own to
    the robot's router, in ``launch --netns``); the others', the clock and the ground
    truth go over ``session_spec``."""
    speed = cfg.sim.speed if speed is None else speed
    keys = SwarmKeys(cfg.comms.swarm)
    ids = [r.id for r in cfg.robots]
    starts = (
        [tuple(p) for p in cfg.sim.start_poses]
        or [tuple(r.start or (0.0, 0.0, 0.0)) for r in cfg.robots]
        or None
    )
    n = max(1, len(ids))
    saved = Path(cfg.persist.dir) / STATE_FILE if cfg.persist.dir else None
    with Simulation(world, cfg.sim, n, start_poses=starts, gui=gui) as sim:
        if not ids:
            ids = [r.name for r in sim.robots]
        index = {rid: k for k, rid in enumerate(ids)}
        if saved is not None and saved.exists():
            resume(sim, saved)
        with contextlib.ExitStack() as stack:
            bus = Bus(stack.enter_context(open_session(session_spec)), "sim")
            stack.callback(bus.close)
            links = _robot_buses(stack, bus, keys, robot_links or {})
            bus.declare_alive(keys.alive("sim", "sim"))
            if links:  # each robot over its own link; the coordinator over the main one
                bus.watch_alive(keys.alive("coordinator", "coordinator"))
            else:
                bus.subscribe(keys.all_robots("cmd_vel"), CmdVel)
                bus.watch_alive(keys.all_alive())
            buses = {rid: links.get(rid, bus) for rid in ids}
            _loop(
                sim,
                bus,
                buses,
                keys,
                ids,
                index,
                stop,
                speed,
                max_lag_s,
                wait_for,
                duration_s,
                saved,
            )
        return sim


def _robot_buses(stack, main: Bus, keys: SwarmKeys, links: dict[str, SessionSpec]) -> dict:
    """A bus on each robot's own link, all received into ``main``'s inbox: it hears that
    robot's commands and liveliness only (the mesh brings the others' too, late)."""
    out = {}
    for rid, spec in links.items():
        b = Bus(stack.enter_context(open_session(spec)), "sim", inbox=main.inbox)
        stack.callback(b.close)
        b.subscribe(keys.robot(rid).cmd_vel, CmdVel)
        b.watch_alive(keys.alive("agent", rid))
        out[rid] = b
    return out


def resume(sim: Simulation, path: Path) -> bool:
    """Go on from a saved state (one scan after it); a state that cannot be read is
    logged and the simulation starts afresh."""
    try:
        sim.restore(json.loads(path.read_text()), steps_ahead=sim.scan_every)
    except (OSError, ValueError, KeyError, TypeError, SimulationError) as e:
        log.error("simulator state %s not used (starting afresh): %s", path, e)
        return False
    log.info("simulator resumed from %s at %.2f s", path, sim.time)
    return True


def save_state(sim: Simulation, path: Path) -> None:
    """``sim.state()`` to ``path``, atomically (a kill never leaves half a file)."""
    tmp = path.with_name(path.name + ".tmp")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp.write_text(json.dumps(sim.state()))
    os.replace(tmp, path)


class _Lockstep:
    """The simulator's side of the agents' acknowledgements: who is alive, which scans
    each agent has not acknowledged yet, when each robot last got a command."""

    def __init__(self, sim, bus, keys: SwarmKeys, ids: list[str], index: dict) -> None:
        self.sim, self.bus, self.keys, self.ids, self.index = sim, bus, keys, ids, index
        self.alive: set[tuple[str, str]] = set()
        self.acked = dict.fromkeys(ids, -1)  # last scan seq each agent has acknowledged
        self.sent: dict[str, list[tuple[int, float]]] = {r: [] for r in ids}  # (seq, t) unacked
        self.sent_wall: dict[str, dict[int, float]] = {r: {} for r in ids}  # seq -> wall time
        self.last_cmd_t = dict.fromkeys(ids, -math.inf)

    def drain(self, timeout: float = 0.0) -> None:
        """Liveliness changes and velocity commands received (with their acks)."""
        for item in self.bus.poll(timeout_s=timeout):
            change = is_alive_change(item)
            if change is not None:
                who = self.keys.alive_name(item.key)
                if who is not None:
                    (self.alive.add if change else self.alive.discard)(who)
                    if who[0] == "agent" and who[1] in self.sent:
                        # a (re)started or lost agent owes no acknowledgements
                        self.sent[who[1]] = []
                        self.acked[who[1]] = -1
                continue
            rid = self.keys.robot_of(item.key)
            if rid not in self.index:
                continue
            msg: CmdVel = item.msg
            self.sim.set_cmd(self.index[rid], msg.v_mps, msg.w_radps)
            self.last_cmd_t[rid] = self.sim.time
            if msg.ack > self.acked[rid]:
                self.acked[rid] = msg.ack
                self.sent[rid] = [(s, t) for s, t in self.sent[rid] if s > msg.ack]
                self.sent_wall[rid] = {s: w for s, w in self.sent_wall[rid].items() if s > msg.ack}

    def forget_lost(self) -> None:
        """A scan unacknowledged for ``ACK_TIMEOUT_S`` of wall time was lost on the way:
        the agent acknowledges later scans only if it is sent some."""
        now_wall = time.monotonic()
        for rid in self.ids:
            sent, wall = self.sent[rid], self.sent_wall[rid]
            if sent and now_wall - wall.get(sent[0][0], now_wall) > ACK_TIMEOUT_S:
                lost = sent.pop(0)
                wall.pop(lost[0], None)
                log.debug("scan %d of %s never acknowledged: treated as lost", lost[0], rid)

    def lagging(self, max_lag_s: float) -> list[str]:
        """Live agents more than ``max_lag_s`` of simulated time behind."""
        return [
            rid
            for rid in self.ids
            if ("agent", rid) in self.alive
            and self.sent[rid]
            and self.sim.time - self.sent[rid][0][1] > max_lag_s
        ]

    def stop_quiet_robots(self) -> None:
        """A robot whose agent went quiet stops."""
        for rid in self.ids:
            if self.sim.time - self.last_cmd_t[rid] > CMD_TIMEOUT_S:
                self.sim.set_cmd(self.index[rid], 0.0, 0.0)

    def sent_scan(self, rid: str, seq: int, t: float) -> None:
        if ("agent", rid) in self.alive:
            self.sent[rid].append((seq, t))
            self.sent_wall[rid][seq] = time.monotonic()


def _wait_for(ls: _Lockstep, stop, wait_for: tuple[str, ...]) -> None:
    """Until the processes that must be up before time starts are."""
    need = set()
    if "agents" in wait_for:
        need |= {("agent", rid) for rid in ls.ids}
    if "coordinator" in wait_for:
        need.add(("coordinator", "coordinator"))
    t_wait = time.monotonic()
    while not stop.is_set() and not need <= ls.alive:
        ls.drain(0.1)
        if time.monotonic() - t_wait > STALL_WARN_S:
            log.warning("waiting for %s", sorted(n for _, n in need - ls.alive))
            t_wait = time.monotonic()


def _loop(
    sim, bus, buses, keys, ids, index, stop, speed, max_lag_s, wait_for, duration_s, saved=None
) -> None:
    ls = _Lockstep(sim, bus, keys, ids, index)
    _wait_for(ls, stop, wait_for)
    log.info("simulation starts: %d robots, speed %.1fx", len(ids), speed)
    wall0, sim0 = time.monotonic(), sim.time
    last_clock = (time.monotonic(), sim.time)
    stall_t = None
    while not stop.is_set() and sim.time < duration_s:
        ls.drain()
        ls.forget_lost()
        lagging = ls.lagging(max_lag_s)  # keep pace with the slowest live agent
        if lagging:
            stall_t = stall_t or time.monotonic()
            if time.monotonic() - stall_t > STALL_WARN_S:
                log.warning("agents %s are behind; waiting", lagging)
                stall_t = time.monotonic()
            ls.drain(0.005)
            wall0, sim0 = time.monotonic(), sim.time  # do not rush to catch up afterwards
            continue
        stall_t = None
        # real-time pacing at the requested speed
        if speed > 0:
            ahead = (sim.time - sim0) / speed - (time.monotonic() - wall0)
            if ahead > 0:
                ls.drain(min(ahead, 0.05))
                continue
        ls.stop_quiet_robots()
        events = sim.step()
        if not events:
            continue
        _publish(sim, ls, bus, buses, keys, ids, index, events)
        now = time.monotonic()
        achieved = (sim.time - last_clock[1]) / max(now - last_clock[0], 1e-9)
        last_clock = (now, sim.time) if now - last_clock[0] > 1.0 else last_clock
        bus.publish(keys.clock, Clock(sim.time, float(np.clip(achieved, 0, 1e6))), sim.time)
        if saved is not None:  # after publishing: a resumed simulator starts one scan later
            save_state(sim, saved)


def _publish(sim, ls: _Lockstep, bus, buses, keys, ids, index, events) -> None:
    """Each robot's odometry and scan on its link, and the ground truth."""
    t = sim.time
    for ev in events:
        rid = ids[ev.robot]
        r = sim.robots[ev.robot]
        o = ev.odom
        link = buses[rid]
        link.publish(
            keys.robot(rid).odom, Odometry(float(o[0]), float(o[1]), float(o[2]), r.v, r.w), t
        )
        # stamped with its first beam
        link.publish(keys.robot(rid).scan, Scan.from_laserscan(ev.scan), ev.scan.stamp)
        ls.sent_scan(rid, link.last_seq(keys.robot(rid).scan), t)
    poses = {rid: tuple(float(v) for v in sim.robots[k].pose) for rid, k in index.items()}
    walls = sum(r.wall_collisions for r in sim.robots)
    robots = sum(r.robot_collisions for r in sim.robots)
    bus.publish(keys.truth, Truth(poses, walls, robots), t)
