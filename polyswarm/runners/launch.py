"""``polyswarm launch``: a whole exploration, every part its own OS process.

Starts the coordinator (which hosts the Zenoh router on a loopback port), the
simulation and one agent per robot, all talking only through Zenoh; watches the
exploration as an observer (merged map against the world's ground truth, robot states,
bytes sent); stops everything on mission end, time limit or Ctrl-C; writes the run
folder. The observer never talks to the robots: it only listens.

    result = launch(LaunchOptions(world="rooms", robots=2), progress=print)
    result.metrics["t99_s"]
"""

from __future__ import annotations

import json
import logging
import math
import os
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

from agents.session import Bus, SessionSpec, open_session
from polyswarm.config import (
    Config,
    RobotEntry,
    config_to_dict,
    save_config,
    with_overrides,
)
from polyswarm.errors import ConfigError, DecodeError, PolyswarmError
from polyswarm.polymap import GridPolyMap
from polyswarm.runners import netns
from polyswarm.runners.children import (
    VIEW,
    Child,
    Supervision,
    _spawn,
    _stop_children,
    free_port,
    make_supervise,
)
from polyswarm.runners.observer import Observer, _write_outputs
from polyswarm.se2 import compose
from protocols.chunks import MapChunk
from protocols.keys import SwarmKeys
from protocols.mapcodec import decode_map
from protocols.messages import (
    Anchor,
    Clock,
    CoordinatorStatus,
    MissionState,
    Pose,
    RobotStatus,
    Truth,
)

log = logging.getLogger(__name__)

RSS_EVERY_S = 5.0  # wall seconds between memory samples of every process
FINAL_FETCH_S = 2.0  # wall seconds to wait for the merged map at the end of a run
START_TIMEOUT_S = 60.0  # wall seconds for all processes to come up


class FaultAction(StrEnum):
    KILL = "kill"  # SIGKILL: the process dies without a word
    STOP = "stop"  # SIGSTOP: frozen (a hung process)
    CONT = "cont"  # SIGCONT: wakes a frozen process
    RESTART = "restart"  # start a killed process again, same arguments
    CUT = "cut"  # --netns: the host's wifi0 link down (out of range)
    RESTORE = "restore"  # --netns: its wifi0 up again


@dataclass(frozen=True)
class Fault:
    action: FaultAction
    target: str  # "coordinator", "sim" or a robot id
    at_s: float  # simulated seconds

    @classmethod
    def parse_many(cls, text: str) -> tuple[Fault, ...]:
        """``kill:r2@20,restart:r2@30`` (action:process@simulated seconds)."""
        out = []
        for item in filter(None, (t.strip() for t in text.split(","))):
            try:
                head, at = item.split("@")
                action, target = head.split(":")
                out.append(cls(FaultAction(action), target, float(at)))
            except ValueError:
                raise ConfigError(
                    f"fault {item!r}: expected action:process@seconds with action one of "
                    f"{', '.join(FaultAction)} (e.g. kill:r2@20)"
                ) from None
        return tuple(sorted(out, key=lambda f: f.at_s))


@dataclass(frozen=True)
class LaunchOptions:
    world: str = "office"
    robots: int = 3
    strategy: str = "hungarian"
    seed: int = 0
    speed: float = 10.0  # simulated seconds per wall second (an upper bound)
    gui: bool = False
    time_limit_s: float = math.inf  # simulated seconds
    wall_limit_s: float = math.inf
    stop_coverage: float = 0.0  # > 0: stop at this coverage (once every robot is merged)
    out: Path | None = None
    config: Config = field(default_factory=Config)
    verbose: bool = False
    netns: bool = False  # each robot and the coordinator a host of its own (``netns``)
    coordinators: int = 1  # the first active, the others standing by (``agents.leadership``)
    faults: tuple[Fault, ...] = ()  # fault injection (tests of reliability)
    link_faults: str = ""  # message loss/duplication/reordering at coordinator and agents
    wrong_anchor: str = ""  # ROBOT:dx,dy,deg: its first frame committed that far off (a fault)
    # ROBOT:dx,dy,deg: its start told that far off where it stands (m, m, deg, in its
    # start's axes): a start measured badly
    start_error: str = ""
    # niceness of the simulator and agent processes: on one computer they stand for the
    # robots' own computers, and ten of them must not starve the coordinator and router
    # (the fleet's shared machine); 0 runs everything at the same priority
    robots_nice: int = 5
    view_port: int | None = None  # also run ``polyswarm view`` serving on this port
    restart: bool = True  # restart children that exit unexpectedly (False: stop the mission)
    # robots at scattered random starts (seeded, 10 m apart where the world allows, random
    # headings; ``scatter``), which with ``unknown_start`` nobody is told: only the
    # simulator and the metrics know them
    scatter: bool = False
    unknown_start: bool = False
    # end with the mission (False: run to the time or wall-clock limit, as a soak test
    # does to see whether memory keeps growing once the building is mapped)
    stop_when_done: bool = True


@dataclass
class LaunchResult:
    out: Path
    metrics: dict
    merged: GridPolyMap


# --- the observer -------------------------------------------------------------------------------


def _inject(fault: Fault, children: list[Child], logs: Path, net=None) -> None:
    """Apply one fault to the named child (a restart replaces it in ``children``), or to
    its host's link (``net``: ``netns.FleetNetwork``)."""
    if fault.action in (FaultAction.CUT, FaultAction.RESTORE):
        if net is None or fault.target not in net.hosts:
            raise ConfigError(
                f"fault {fault}: links are cut with --netns, on a robot or the coordinator"
            )
        (net.cut if fault.action == FaultAction.CUT else net.restore)(fault.target)
        return
    k = next((i for i, c in enumerate(children) if c.name == fault.target), None)
    if k is None:
        raise ConfigError(f"fault {fault}: no process named {fault.target!r}")
    c = children[k]
    log.warning("fault injection at %.1f s: %s %s", fault.at_s, fault.action, c.name)
    if fault.action == FaultAction.RESTART:
        if c.proc.poll() is None:
            c.proc.kill()
            c.proc.wait()
        children[k] = _spawn(c.name, c.args, logs, c.verbose, c.env, c.nice, c.wrap)
    else:
        sig = {
            FaultAction.KILL: signal.SIGKILL,
            FaultAction.STOP: signal.SIGSTOP,
            FaultAction.CONT: signal.SIGCONT,
        }[fault.action]
        if c.proc.poll() is None:
            c.proc.send_signal(sig)


# --- the launch ----------------------------------------------------------------------------------


def prepare(opts: LaunchOptions):
    """World, effective config (robot ids and start poses), run folder."""
    from sim import load_world, scattered_start_poses, spread_start_poses

    world = load_world(opts.world, seed=opts.seed)
    cfg = opts.config
    if opts.scatter or opts.unknown_start:
        starts = scattered_start_poses(world, opts.robots, cfg.sim.robot.radius_m, opts.seed)
    else:
        starts = spread_start_poses(world, opts.robots, cfg.sim.robot.radius_m)
    port = free_port()
    cfg = with_overrides(
        cfg,
        {
            "sim": {"world": opts.world, "seed": opts.seed, "speed": opts.speed},
            "explore": {"strategy": opts.strategy},
            "comms": {"endpoint": f"tcp/127.0.0.1:{port}"},
        },
    )
    starts = [tuple(map(float, p)) for p in starts]
    if opts.unknown_start:  # the swarm is told nothing; the simulator puts them there
        cfg = _with_robots(cfg, tuple(RobotEntry(f"r{k + 1}") for k in range(len(starts))))
        cfg = with_overrides(cfg, {"sim": {"start_poses": [list(p) for p in starts]}})
    else:
        told = _told_starts(starts, opts.start_error)
        cfg = _with_robots(cfg, tuple(RobotEntry(f"r{k + 1}", p) for k, p in enumerate(told)))
        if told != starts:  # the simulator puts them where they really are
            cfg = with_overrides(cfg, {"sim": {"start_poses": [list(p) for p in starts]}})
    out = opts.out or Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    if not cfg.persist.dir:  # agents and coordinator keep their maps in the run folder
        cfg = with_overrides(cfg, {"persist": {"dir": str((out / "state").resolve())}})
    (out / "logs").mkdir(exist_ok=True)
    save_config(cfg, out / "config.toml")
    return world, cfg, out


def _told_starts(starts: list[tuple], start_error: str) -> list[tuple]:
    """The starts the swarm is told: one of them off by ``start_error`` (ROBOT:dx,dy,deg)."""
    from agents.anchoring import robot_offset

    off = robot_offset(start_error, "start error")
    if off is None:
        return starts
    k = int(off[0][1:]) - 1 if off[0][1:].isdigit() else -1
    if not (off[0].startswith("r") and 0 <= k < len(starts)):
        raise ConfigError(f"start error {start_error!r}: no robot {off[0]} of {len(starts)}")
    told = list(starts)
    told[k] = tuple(float(v) for v in compose(starts[k], off[1]))
    return told


def _with_robots(cfg: Config, robots: tuple[RobotEntry, ...]) -> Config:
    import dataclasses

    return dataclasses.replace(cfg, robots=robots)


def launch(
    opts: LaunchOptions,
    progress: Callable[[Observer, float], None] | None = None,
    stop: threading.Event | None = None,
) -> LaunchResult:
    world, cfg, out = prepare(opts)
    ids = [r.id for r in cfg.robots]
    stop = stop or threading.Event()
    children: list[Child] = []
    obs = Observer(world, cfg, ids)
    sup = Supervision()
    t0 = time.monotonic()
    error: str | None = None
    net = _network(opts, ids, out)
    try:
        _start(children, opts, cfg, netns.Hosts(net, cfg.comms.endpoint), ids, out)
        with open_session(SessionSpec.client(cfg.comms.endpoint)) as session:
            bus = Bus(session, "observer")
            try:
                keys = _listen(bus, cfg)
                error = _watch(bus, keys, obs, opts, children, stop, progress, t0, sup, net)
                obs.sample_memory(children, time.monotonic() - t0)  # as the run ended
                if error != "interrupted":
                    _final_sync(bus, keys, obs)
            finally:
                bus.close()
    finally:
        codes, running = _stop_children(children)
        if net is not None:
            net.remove()
    m = obs.metrics(time.monotonic() - t0, opts)
    m["exit_codes"] = codes
    m["crashed_processes"] = _crashed(opts, codes, running)
    m["restarts"] = dict(sup.restarts)  # children restarted after exiting unexpectedly
    m["stopped_because"] = error or "unknown"
    if opts.coordinators > 1:
        m["leaders"] = [[t, n, s, round(w - t0, 3)] for t, n, s, w in obs.leaders]
        m["takeover_s"] = _takeovers(obs)
    if net is not None:
        m["link_outages"] = obs.outages.to_list()
        m["maps_agree"] = netns.maps_agree(Path(cfg.persist.dir), ids)
    m["config"] = config_to_dict(cfg)["explore"]
    m["profile"] = cfg.profile
    _write_outputs(out, obs, m, cfg.map.whole_map_precision_m)
    return LaunchResult(out, m, obs.merged)


def _start(children: list[Child], opts: LaunchOptions, cfg: Config, hosts, ids, out: Path):
    """The router, the coordinators, the simulator, the agents and the view, each on
    its host (``hosts``), appended to ``children`` as they start."""
    conf, logs = str(out / "config.toml"), out / "logs"
    # a router of its own: the others keep talking while the coordinator restarts
    children.append(_spawn("router", ["router", "--listen", hosts.root], logs, False))
    faulty = {"POLYSWARM_LINK_FAULTS": opts.link_faults} if opts.link_faults else {}
    wrong = {"POLYSWARM_WRONG_ANCHOR": opts.wrong_anchor} if opts.wrong_anchor else {}
    args = ["coordinator", "--config", conf, *hosts.coordinator_args()]
    wrap = hosts.wrap("coordinator")
    children.append(_spawn("coordinator", args, logs, opts.verbose, faulty | wrong, wrap=wrap))
    for name in _standbys(opts):
        args = ["coordinator", "--config", conf, "--name", name, "--standby"]
        args += hosts.coordinator_args(name)
        children.append(_spawn(name, args, logs, opts.verbose, faulty, wrap=hosts.wrap(name)))
    sim_args = ["sim", "--serve", "--config", conf, "--world", opts.world]
    sim_args += ["--seed", str(opts.seed), "--speed", str(opts.speed), "--wait-coordinator"]
    sim_args += [*hosts.sim_args(ids), *(["--gui"] if opts.gui else [])]
    nice = opts.robots_nice
    children.append(_spawn("sim", sim_args, logs, opts.verbose, nice=nice))
    for rid in ids:
        agent_args = ["agent", "--id", rid, "--config", conf, *hosts.agent_args(rid)]
        children.append(_spawn(rid, agent_args, logs, opts.verbose, faulty, nice, hosts.wrap(rid)))
    if opts.view_port is not None:
        view_args = ["view", "--config", conf, "--connect", cfg.comms.endpoint]
        view_args += ["--port", str(opts.view_port), "--stats", str(logs / "view.json")]
        children.append(_spawn(VIEW, view_args, logs, False))


def _listen(bus, cfg: Config) -> SwarmKeys:
    """The observer's subscriptions: everything the swarm says, nothing it is told."""
    keys = SwarmKeys(cfg.comms.swarm)
    bus.subscribe(keys.clock, Clock)
    bus.subscribe(keys.truth, Truth)
    bus.subscribe(keys.coordinator_status, CoordinatorStatus)
    bus.subscribe(keys.merged_delta, MapChunk)
    bus.subscribe(keys.all_robots("status"), RobotStatus)
    bus.subscribe(keys.all_robots("pose"), Pose)
    bus.subscribe(keys.all_robots("map/delta"), MapChunk)
    bus.subscribe(keys.all_anchors, Anchor)
    return keys


def _crashed(opts: LaunchOptions, codes: dict, running: set[str]) -> list[str]:
    """Children that died for good: not stopped by the launch, not killed on purpose."""
    injected = {f.target for f in opts.faults if f.action == FaultAction.KILL}
    return sorted(
        k
        for k, v in codes.items()
        if v not in (0, -signal.SIGTERM, 130)
        and not ((k in injected or k in running) and v == -signal.SIGKILL)
    )


def _network(opts: LaunchOptions, ids: list[str], out: Path):
    """``--netns``: the fleet's hosts in namespaces of their own (``netns``); else None."""
    cuts = [f for f in opts.faults if f.action in (FaultAction.CUT, FaultAction.RESTORE)]
    if not opts.netns:
        if cuts:
            raise ConfigError(f"fault {cuts[0]}: links are cut with --netns")
        return None
    run = os.urandom(2).hex()
    (out / "logs" / "netns.json").write_text(json.dumps({"run": run, "hosts": ids}))
    hosts = ["coordinator", *_standbys(opts), *ids]
    return netns.FleetNetwork.create(run, hosts, out / "sockets")


def _takeovers(obs: Observer) -> list[float]:
    """Wall seconds from each kill of a coordinator to the first status of a new leader."""
    out = []
    for lost in obs.coordinator_lost:
        after = [w for _, _, _, w in obs.leaders[1:] if w >= lost]
        if after:
            out.append(round(after[0] - lost, 3))
    return out


def _standbys(opts: LaunchOptions) -> list[str]:
    return [f"coordinator{k}" for k in range(2, opts.coordinators + 1)]


def _watch(bus, keys, obs: Observer, opts, children, stop, progress, t0, sup, net=None) -> str:
    pending = list(opts.faults)
    supervise = make_supervise(sup)
    faulted: set[str] = set()  # killed by fault injection (not a reason to stop)
    logs = children[0].log_path.parent
    last_progress = 0.0
    last_rss = -math.inf
    up = False
    while True:
        for item in bus.poll(timeout_s=0.05):
            try:
                obs.handle(keys, item)
            except (DecodeError, PolyswarmError) as e:
                log.warning("observer: %s", e)
        if obs.need_resync:
            got = bus.fetch_map(keys.merged_map, timeout_s=2.0)
            if got is not None:
                try:
                    obs.merged = decode_map(got[0])
                    obs.need_resync = False
                except DecodeError as e:
                    log.warning("observer: bad merged map: %s", e)
        up = up or obs.sim_t > 0
        obs.sample()
        if time.monotonic() - last_rss >= RSS_EVERY_S:
            last_rss = time.monotonic()
            obs.sample_memory(children, last_rss - t0)
        now = time.monotonic()
        if progress is not None and now - last_progress >= 0.5:
            last_progress = now
            progress(obs, now - t0)
        if stop.is_set():
            return "interrupted"
        while pending and obs.sim_t >= pending[0].at_s:
            fault = pending.pop(0)
            _inject(fault, children, logs, net)
            if fault.action == FaultAction.KILL and fault.target.startswith("coordinator"):
                obs.coordinator_lost.append(now)
            if fault.action == FaultAction.CUT:
                view = obs.robots.get(fault.target)
                obs.outages.cut(fault.target, obs.sim_t, view.keyframes if view else 0)
            elif fault.action == FaultAction.RESTORE:
                obs.outages.restore(fault.target, obs.sim_t)
            if fault.action == FaultAction.KILL:
                faulted.add(fault.target)
            elif fault.action == FaultAction.RESTART:
                faulted.discard(fault.target)
        failed = supervise(children, faulted, opts.restart, logs, now)
        if failed:
            return failed
        if obs.mission == MissionState.DONE and opts.stop_when_done:
            return "mission done"
        if obs.sim_t >= opts.time_limit_s:
            return "time limit"
        if now - t0 >= opts.wall_limit_s:
            return "wall-clock limit"
        if not up and now - t0 > START_TIMEOUT_S:
            return "processes did not start"
        if (
            opts.stop_coverage > 0
            and obs.coverage
            and obs.coverage[-1][1] >= opts.stop_coverage
            and not obs.unplaced()  # robots not merged yet: their maps are not in it
        ):
            return f"coverage {opts.stop_coverage:.0%} reached"


def _final_sync(bus, keys, obs: Observer) -> None:
    """The coordinator's merged map as it is now (deltas still in flight would otherwise
    be missing from the outputs), and a last coverage sample."""
    got = bus.fetch_map(keys.merged_map, timeout_s=FINAL_FETCH_S)
    if got is not None:
        try:
            m = decode_map(got[0])
            if m.version > obs.merged.version:
                obs.merged = m
        except DecodeError as e:
            log.warning("observer: bad merged map: %s", e)
    if obs.coverage and obs.sim_t <= obs.coverage[-1][0]:
        obs.coverage[-1] = (obs.coverage[-1][0], obs.coverage_now())
    else:
        obs.coverage.append((obs.sim_t, obs.coverage_now()))
