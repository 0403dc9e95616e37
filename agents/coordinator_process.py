"""The coordinator's process: a Zenoh session wired to ``agents.coordinator.Coordinator``.

``run_coordinator`` subscribes the robots' updates and statuses, serves the merged map,
runs the cycle, the joint pose graph and the frames' matching, and publishes what the
cycle decides; the helpers below turn messages into calls of the coordinator."""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from pathlib import Path

import numpy as np

from agents import persist
from agents.coordinator import Coordinator
from agents.leadership import Leadership
from agents.merger import MergeProcess
from agents.replay import ReplayPool
from agents.robotmaps import DRAIN_TIMEOUT_S
from polyswarm.config import Config, known_starts
from polyswarm.errors import DecodeError, MapError, PolyswarmError
from polyswarm.polymap import MapDelta
from protocols.chunks import MapChunk, MapKind
from protocols.keys import SwarmKeys
from protocols.mapcodec import (
    decode_any_map,
    encode_delta,
    encode_map,
)
from protocols.messages import Assignment, CoordinatorStatus, Pose, RobotStatus

log = logging.getLogger(__name__)


def run_coordinator(
    cfg: Config,
    session_spec,
    stop: threading.Event | None = None,
    name: str = "coordinator",
    standby: bool = False,
) -> Coordinator:
    """Run the coordinator until ``stop`` is set (or SIGINT/SIGTERM). ``standby``: start
    silent, and take over when the active one is gone (``agents.leadership``); a
    coordinator other than ``coordinator`` keeps its state in a folder of its name."""
    from agents.session import Bus, open_session, stop_on_signals

    stop = stop or stop_on_signals()
    node = CoordinatorNode(cfg, name, standby)
    with open_session(session_spec) as session:
        node.start(Bus(session, name))
        try:
            while not stop.is_set():
                node.step()
        finally:
            node.close()
    return node.coord


class CoordinatorNode:
    """The coordinator on a bus: messages in (``handle``), robot maps healed
    (``heal``), merges, cycles and what they decide out (``tick``)."""

    def __init__(self, cfg: Config, name: str = "coordinator", standby: bool = False) -> None:
        from agents.anchoring import Anchoring
        from agents.joint import JointCorrections

        self.cfg, self.name = cfg, name
        self.keys = SwarmKeys(cfg.comms.swarm)
        starts = known_starts(cfg.robots)
        self.robots = {rid: tuple(st) for rid, st in starts.items() if st is not None}
        self.coord = Coordinator(cfg, self.robots)
        # robots whose start poses were not given explore alone until their frames are found
        self.anchoring = Anchoring(cfg, [rid for rid, st in starts.items() if st is None])
        self.joint = JointCorrections() if cfg.explore.joint_graph else None
        self.state_dir = cfg.persist.dir
        if self.state_dir and name != "coordinator":
            self.state_dir = str(Path(self.state_dir) / name)
        self.journal = persist.CoordinatorJournal(self.state_dir) if self.state_dir else None
        if self.state_dir:
            self._restore()
        self.lead = Leadership(name, active=not standby, since=time.monotonic())
        self.peers: set[str] = set()  # coordinators alive, active or standing by
        self.resync: set[str] = set()  # robots whose maps are fetched whole
        self.bus = self.out = self.token = self.pool = self.merger = None

    def _restore(self) -> None:
        merged, robot_maps = persist.load_coordinator(self.state_dir)
        self.coord.restore(merged, robot_maps)
        if merged is not None:
            log.info(
                "restored the merged map (version %d, %.1f m2) and %d robot maps from %s",
                merged.version,
                merged.explored_area(),
                len(robot_maps),
                self.state_dir,
            )

    def start(self, bus) -> None:
        """Worker processes, subscriptions, the map queryable, liveliness."""
        cfg, keys, coord, lead = self.cfg, self.keys, self.coord, self.lead
        self.bus, self.out = bus, Gate(bus, lead)  # what only the active coordinator sends
        if cfg.explore.replay_workers:
            # the robots' map copies are journaled by the pool's processes
            self.pool = coord.use_pool(ReplayPool(cfg.explore.replay_workers, self.state_dir))
        if cfg.explore.merge_process:
            self.merger = coord.use_merger(MergeProcess(coord.merged, cfg.nav))
        bus.subscribe(keys.all_robots("map/delta"), MapChunk)
        bus.subscribe(keys.all_robots("pose"), Pose)
        bus.subscribe(keys.all_robots("status"), RobotStatus)
        precision_m = cfg.map.whole_map_precision_m  # a whole map goes at 1 mm
        bus.serve_map(
            keys.merged_map,
            lambda: (
                (encode_map(coord.merged, precision_m), coord.merged.version)
                if lead.active
                else None
            ),
        )
        bus.subscribe(keys.coordinator_status, CoordinatorStatus)
        bus.subscribe(keys.all_assignments, Assignment)
        self.token = bus.declare_alive(keys.alive(_role(lead), self.name))
        for role in ("agent", "coordinator", "standby"):
            bus.watch_alive(keys.all_alive(role))
        log.info("coordinator up: robots %s, strategy %s", list(self.robots), coord.strategy)

    def step(self) -> None:
        for item in self.bus.poll(timeout_s=0.05):
            try:
                self.handle(item)
            except DecodeError as e:
                log.warning("rejected %s: %s", item.key, e)
            except PolyswarmError as e:
                log.warning("%s: %s", item.key, e)
        if self.lead.due(time.monotonic(), self.peers):
            self.lead.take_over(time.monotonic())
            self.coord.adopt(self.lead.assignments, self.lead.max_target)
            self.token = _swap_role(self.bus, self.keys, self.lead, self.token)
        self.heal()
        self.tick()

    def handle(self, item) -> None:
        """One message: liveliness, another coordinator's, or a robot's."""
        from agents.session import is_alive_change

        keys, coord, anchoring = self.keys, self.coord, self.anchoring
        alive = is_alive_change(item)
        if alive is not None:
            who = keys.alive_name(item.key)
            if who is not None and who[0] in ("coordinator", "standby"):
                (self.peers.add if alive else self.peers.discard)(who[1])
            elif who is not None:
                anchoring.owner(who[1], coord).on_alive(who[1], alive)
            return
        if _leader_message(self.lead, keys, item):
            self.token = _swap_role(self.bus, keys, self.lead, self.token)
            return
        rid = keys.robot_of(item.key)
        if rid is None:
            return
        msg = item.msg
        if isinstance(msg, Pose):
            anchoring.sighted(rid, item.stamp_s, msg)
            if rid in anchoring.waiting:
                anchoring.on_pose(rid, msg.frame, msg.map_version, coord, msg.own)
        owner = anchoring.owner(rid, coord)
        if owner is not coord:  # exploring alone: its own coordinator
            _robot_message(owner, rid, item, self.resync)
        elif isinstance(msg, MapChunk) and item.payload is not None:
            try:
                changed = coord.on_robot_update(rid, item.stamp_s, msg.kind, item.payload)
            except MapError as e:
                _resync(coord, rid, e, self.resync)
            else:  # journaled as the cells it changed (restores need no merge)
                raw = item.payload if msg.kind == MapKind.DELTA else None
                _journal_cells(self.journal, coord, rid, changed, raw)
        else:
            _robot_message(coord, rid, item, self.resync)

    def heal(self) -> None:
        """Robot maps that did not apply (a gap, a lost last delta): fetched whole."""
        coord, resync = self.coord, self.resync
        for rid, got in coord.take_in():  # replayed and journaled on the pool
            if isinstance(got, MapError):
                _resync(coord, rid, got, resync)
        behind = set(coord.needs_resync()) - resync
        coord.gaps += len(behind)  # a last delta lost: announced, never received
        resync |= behind
        for solo in self.anchoring.coordinators():
            resync |= set(solo.needs_resync())
        for rid in list(resync):
            if self._fetch(rid):
                resync.discard(rid)

    def _fetch(self, rid: str) -> bool:
        owner = self.anchoring.owner(rid, self.coord)
        log.info("fetching the full map of %s", rid)
        owner.map_fetches += 1
        with owner.timed("fetch"):  # blocking: it delays the cycle
            got = self.bus.fetch_map(self.keys.robot(rid).map, timeout_s=2.0)
        owner.robot(rid).behind_since = owner.now  # next try after a pause
        if got is None:
            return False
        owner.fetch_bytes += len(got[0])
        try:
            before = owner.robot(rid).map
            with owner.timed("fetch"):
                owner.on_robot_map(rid, decode_any_map(got[0]))
        except PolyswarmError as e:
            log.warning("map of %s refused: %s", rid, e)
            return False
        coord = self.coord
        mine = owner is coord and coord.pool is None  # else its worker's
        if mine and coord.robot(rid).map is not before:
            with coord.timed("journal"):
                persist.record(self.journal, "robot_map", rid, coord.robot(rid).map)
        return True

    def tick(self) -> None:
        """Solo coordinators' cycles, anchors, priors, the merge and the cycle, sent."""
        keys, coord, out, anchoring = self.keys, self.coord, self.out, self.anchoring
        for solo in anchoring.coordinators():  # their maps are not published
            if solo.flush_due():
                solo.flush()
            if solo.due():
                for rid, a in solo.cycle().assignments.items():
                    solo.bytes_sent += out.publish(keys.assignment(rid), a, solo.now, reliable=True)
        coord.frames_pending = tuple(anchoring.waiting)
        now = max([coord.now, *(s.now for s in anchoring.coordinators())])
        for rid, anchor in anchoring.tick(coord, now):
            if anchor.own and coord.pool is None:  # withdrawn: journaled aside
                persist.record(self.journal, "robot_withdrawn", rid)
            coord.bytes_sent += out.publish(keys.anchor(rid), anchor, now, reliable=True)
        audits = set(anchoring.audits)
        for rid, priors in self.joint.tick(coord, now, audits) if self.joint else []:
            coord.bytes_sent += out.publish(keys.priors(rid), priors, now, reliable=True)
        if coord.flush_due():
            delta = coord.flush()
            with coord.timed("publish"):
                _publish_delta(out, keys, coord, delta, self.journal)
        if coord.due():
            res = coord.cycle()
            with coord.timed("publish"):  # counted into the next cycle
                _publish_delta(out, keys, coord, res.merged_delta, self.journal)
                for rid, a in res.assignments.items():
                    coord.bytes_sent += out.publish(
                        keys.assignment(rid), a, coord.now, reliable=True
                    )
            if res.status is not None:
                status = dataclasses.replace(res.status, leader=self.name, term=self.lead.term)
                coord.bytes_sent += out.publish(
                    keys.coordinator_status, status, coord.now, reliable=True
                )

    def close(self) -> None:
        """Workers stopped; what the robots sent merged and journaled; a summary logged."""
        coord = self.coord
        self.anchoring.close()
        if self.joint is not None:
            self.joint.close()
        self.bus.close()
        if self.pool is not None:  # what robots sent is replayed and journaled, merged below
            coord.drain()
            self.pool.close()
        if self.journal is not None:  # what the robots sent is merged before it is written
            delta = coord.flush(wait_s=DRAIN_TIMEOUT_S)
            if delta is not None:
                persist.record(self.journal, "merged", encode_delta(delta), coord.merged)
        if self.merger is not None:
            self.merger.close()
        _log_summary(coord, self.pool)


def _log_summary(coord: Coordinator, pool) -> None:
    log.info(
        "robot map updates: %d merges replayed, %d cell deltas applied, %d map fetches",
        coord.replayed_merges,
        coord.applied_deltas,
        coord.map_fetches,
    )
    if coord.stage_ms:
        log.info(
            "coordinator thread's work by stage: %s",
            ", ".join(f"{k} {v:.0%}" for k, v in coord.stage_shares().items()),
        )
    if coord.merger_cpu_ms:
        log.info(
            "merges on their process: processor time p95 %.1f ms, %.1f s in all; "
            "sent to taken in p95 %.0f ms",
            np.percentile(coord.merger_cpu_ms, 95),
            sum(coord.merger_cpu_ms) / 1e3,
            np.percentile(coord.merge_lag_ms, 95),
        )
    if coord.replay_cpu_ms or coord.worker_replay_cpu_ms:
        r = np.asarray(coord.replay_cpu_ms or coord.worker_replay_cpu_ms)
        log.info(
            "replays%s: processor time p50 %.1f ms, p95 %.1f ms, %.1f s in all",
            "" if pool is None else f" on {pool.workers} process(es)",
            np.median(r),
            np.percentile(r, 95),
            r.sum() / 1e3,
        )


class Gate:
    """The bus's sending side, open only while this coordinator is the active one."""

    def __init__(self, bus, lead: Leadership) -> None:
        self.bus, self.lead = bus, lead

    def publish(self, *args, **kw) -> int:
        return self.bus.publish(*args, **kw) if self.lead.active else 0

    def publish_map(self, *args, **kw) -> int:
        return self.bus.publish_map(*args, **kw) if self.lead.active else 0


def _role(lead: Leadership) -> str:
    return "coordinator" if lead.active else "standby"


def _swap_role(bus, keys: SwarmKeys, lead: Leadership, token):
    """The liveliness token of this coordinator's role now (robots count only actives)."""
    bus.undeclare(token)
    return bus.declare_alive(keys.alive(_role(lead), lead.name))


def _leader_message(lead: Leadership, keys: SwarmKeys, item) -> bool:
    """Another coordinator's status or assignment: heard by the election; True when
    this coordinator just stepped down."""
    msg = item.msg
    if isinstance(msg, CoordinatorStatus):
        return lead.heard_status(msg, time.monotonic())
    if isinstance(msg, Assignment) and item.sender != lead.name:
        lead.heard_assignment(item.key.rsplit("/", 1)[-1], msg)
    return False


def _robot_message(c: Coordinator, rid: str, item, resync: set) -> None:
    """A robot's pose, status or map update; the map update unjournaled (a coordinator
    of a robot exploring alone, ``agents.anchoring``)."""
    msg = item.msg
    if isinstance(msg, Pose):
        c.on_pose(rid, item.stamp_s, msg)
    elif isinstance(msg, RobotStatus):
        c.on_status(rid, item.stamp_s, msg)
    elif isinstance(msg, MapChunk) and item.payload is not None:
        try:
            c.on_robot_update(rid, item.stamp_s, msg.kind, item.payload)
        except MapError as e:
            _resync(c, rid, e, resync)


def _resync(c: Coordinator, rid: str, e: MapError, resync: set) -> None:
    log.info("resync of %s: %s", rid, e)
    c.gaps += 1
    resync.add(rid)


def _journal_cells(
    journal: persist.CoordinatorJournal | None,
    coord: Coordinator,
    rid: str,
    changed: MapDelta | None,
    wire: bytes | None = None,
) -> None:
    """A robot map update that applied, journaled as the cells it changed (``wire``:
    already encoded, as a cell delta arrives)."""
    if journal is None or changed is None:
        return
    with coord.timed("journal"):  # encoding it is the journal's work too
        wire = wire or encode_delta(changed)
        persist.record(journal, "robot_delta", rid, wire, coord.robot(rid).map)


def _publish_delta(
    bus,
    keys: SwarmKeys,
    coord: Coordinator,
    delta: MapDelta | None,
    journal: persist.CoordinatorJournal | None = None,
) -> None:
    if delta is None:
        return
    wire = encode_delta(delta)
    persist.record(journal, "merged", wire, coord.merged)  # on disk before anyone has seen it
    coord.bytes_sent += bus.publish_map(
        keys.merged_delta, MapKind.DELTA, wire, delta.base_version, delta.version, coord.now
    )
