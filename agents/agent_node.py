"""The agent's process: a Zenoh session wired to ``agents.robot.RobotAgent``.

``run_agent`` subscribes the robot's sensors and what the coordinator sends, feeds the
agent scan by scan (each waits briefly for the odometry of its time), journals its map
before anyone sees it, and sends what the agent decides: velocity commands, map
updates, poses and status."""

from __future__ import annotations

import logging
import math
import threading
import time

import numpy as np

from agents import persist
from agents.leadership import Following
from agents.robot import Outbox, RobotAgent, scan_end_s, scan_from_message
from polyswarm.config import Config, SensorSource
from polyswarm.errors import DecodeError, MapError, PolyswarmError
from protocols.chunks import MAP_KIND_OF, MapChunk, MapKind
from protocols.keys import SwarmKeys
from protocols.mapcodec import (
    decode_delta,
    decode_map,
    encode_cells_map,
    encode_delta,
    encode_updates,
)
from protocols.messages import Anchor, Assignment, CoordinatorStatus, Odometry, Pose, Priors, Scan

log = logging.getLogger(__name__)

SCAN_WAIT_S = 0.2  # wall seconds without odometry after which a scan goes without it


def run_agent(
    robot_id: str,
    cfg: Config,
    start_pose,
    session_spec,
    stop: threading.Event | None = None,
    duration_s: float = 0.0,
    attach=None,
    frame_known: bool = True,
) -> RobotAgent:
    """Run the agent on a Zenoh session until ``stop`` is set (or SIGINT/SIGTERM).

    ``attach(session, agent, stop)``, if given, is called once the agent listens (a log
    player feeding it, for example); it may return a function called at shutdown."""
    from agents.session import Bus, open_session, stop_on_signals

    stop = stop or stop_on_signals()
    node = AgentNode(robot_id, cfg, start_pose, frame_known)
    t_end = time.monotonic() + duration_s if duration_s > 0 else math.inf
    with open_session(session_spec) as session:
        node.start(Bus(session, robot_id))
        detach = attach(session, node.agent, stop) if attach is not None else None
        try:
            while not stop.is_set() and time.monotonic() < t_end:
                node.step(stop)
        finally:
            if detach is not None:
                detach()
            node.close()
    return node.agent


class AgentNode:
    """A robot agent on a bus: messages in (``handle``), scans processed as their
    odometry arrives, the merged map fetched when it is behind (``step``)."""

    def __init__(self, robot_id: str, cfg: Config, start_pose, frame_known: bool) -> None:
        self.id, self.cfg = robot_id, cfg
        self.keys = SwarmKeys(cfg.comms.swarm)
        self.me = self.keys.robot(robot_id)
        self.agent = RobotAgent(robot_id, cfg, start_pose, frame_known)
        self.state_dir = cfg.persist.dir
        if self.state_dir:
            self._resume()
        self.waiting: list = []  # (wall time, scan item) waiting for odometry
        self.odom_wall = -math.inf  # wall time the last odometry message arrived
        self.need_merged = False
        self.behind_since: float | None = None  # the merged map we hold is older
        self.leader = Following()  # the coordinator it takes assignments from
        self.bus = self.sink = self.frames = self.ros_node = None

    def _resume(self) -> None:
        saved = persist.load_agent(self.state_dir, self.id)
        if saved is None:
            return
        self.agent.resume(*saved)
        log.info(
            "%s: resumed from %s (map version %d, %.1f m2, pose %s)",
            self.id,
            self.state_dir,
            saved.map.version,
            saved.map.explored_area(),
            np.round(saved.pose, 3).tolist(),
        )

    def start(self, bus) -> None:
        """Sensors, subscriptions, the robot map's queryable, liveliness."""
        from agents.sources import CommandSink, RmwZenohNode, RosFrames, subscribe_sensors

        cfg, keys, me, agent = self.cfg, self.keys, self.me, self.agent
        self.bus, self.frames = bus, RosFrames()
        rmw = None
        if cfg.agent.source == SensorSource.RMW_ZENOH:
            rmw = RmwZenohNode(bus, cfg.agent, self.id)
            rmw.declare()
        if cfg.agent.source == SensorSource.ROS2_NODE:
            from agents.ros2_node import Ros2Node

            self.ros_node = Ros2Node(bus, cfg.agent, self.id, self.frames)
            sensors = [self.ros_node.scan_topic, self.ros_node.odom_topic]
        else:
            sensors = subscribe_sensors(bus, me, cfg.agent, self.frames)
        self.sink = CommandSink(bus, me, cfg.agent, rmw, self.ros_node)
        bus.subscribe(keys.all_robots("pose"), Pose)
        bus.subscribe(keys.assignment(self.id), Assignment)
        bus.subscribe(keys.anchor(self.id), Anchor)
        bus.subscribe(keys.priors(self.id), Priors)
        bus.subscribe(keys.merged_delta, MapChunk)
        bus.subscribe(keys.coordinator_status, CoordinatorStatus)
        # all cells exactly: the coordinator's copy must be bit-identical to replay merges
        bus.serve_map(
            me.map,
            lambda: (encode_cells_map(agent.slam.map), agent.slam.map.version),
            MapKind.DELTA,
        )
        bus.declare_alive(keys.alive("agent", self.id))
        bus.watch_alive(keys.all_alive("coordinator"))
        log.info(
            "agent %s up (start pose %s, sensors on %s, output %s)",
            self.id,
            tuple(agent.start_pose),
            sensors,
            cfg.agent.output,
        )

    def _nav2_outcome(self) -> None:
        """Nav2's word on the goal: it reached it, or it failed (the coordinator told)."""
        done = self.ros_node.nav.outcome()
        a = self.agent.assignment
        if done is None or a is None or a.target != done.target:
            return
        from agents.ros2_action import GoalState

        if done.state != GoalState.CANCELED:  # canceled: by us, for the next goal
            self.agent.behaviour.on_nav_result(done.state == GoalState.SUCCEEDED, done.detail)

    def step(self, stop: threading.Event) -> None:
        agent = self.agent
        agent.use_tf_mount(self.frames.mount())
        for item in self.bus.poll(timeout_s=0.05):
            if stop.is_set():  # a backlog of scans must not outlast the shutdown grace
                break
            try:
                self.handle(item)
            except DecodeError as e:
                log.warning("%s: rejected %s: %s", self.id, item.key, e)
                agent.stats.refused += 1
            except PolyswarmError as e:
                log.warning("%s: %s", self.id, e)
        # a scan goes without the odometry of its time only once odometry has gone quiet:
        # while it flows (late, or queued behind a busy step) the scan waits for it
        while (
            self.waiting
            and time.monotonic() - max(self.waiting[0][0], self.odom_wall) > SCAN_WAIT_S
        ):
            self.process_scan(self.waiting.pop(0)[1])
        if self.ros_node is not None:
            self.ros_node.publish_map(agent.planning_map, agent.target_xy)
            self.ros_node.publish_robots(agent.id, agent.pose, agent.path_left(), agent.peers)
            self.ros_node.publish_map_to_odom(agent.pose, agent.slam.odom)
            if self.ros_node.nav is not None:
                self._nav2_outcome()
        if self.need_merged and agent.in_shared_frame:
            self._fetch_merged()

    def handle(self, item) -> None:
        from agents.session import is_alive_change

        agent, msg = self.agent, item.msg
        alive = is_alive_change(item)
        if alive is not None:
            self.need_merged |= alive
            who = self.keys.alive_name(item.key)
            if who is not None and who[0] == "coordinator":
                agent.on_coordinator_alive(who[1], alive)
        elif isinstance(msg, Odometry):
            self.odom_wall = time.monotonic()
            agent.on_odom(item.stamp_s, msg)
            while self.waiting and scan_end_s(self.waiting[0][1]) <= item.stamp_s:
                self.process_scan(self.waiting.pop(0)[1])
        elif isinstance(msg, Scan):
            agent.use_tf_mount(self.frames.mount())  # before the first scan
            # odometry and scans travel on separate keys: a scan waits (briefly) for the
            # odometry of its time
            if agent.latest_odom_s >= scan_end_s(item):
                self.process_scan(item)
            else:
                self.waiting.append((time.monotonic(), item))
        elif isinstance(msg, Pose):
            rid = self.keys.robot_of(item.key)
            if rid is not None:
                agent.on_peer_pose(rid, item.stamp_s, msg)
        elif isinstance(msg, Assignment):
            if self.leader.admits(item.sender, msg):
                self._assigned(msg, item.stamp_s)
        elif isinstance(msg, Anchor):
            agent.on_anchor(msg)
            self.need_merged = True
        elif isinstance(msg, Priors):
            agent.on_priors(msg)
        elif isinstance(msg, MapChunk) and item.payload is not None:
            try:
                agent.on_merged_delta(decode_delta(item.payload))
            except MapError:  # a gap (or no map yet): resync
                self.need_merged = True
        elif isinstance(msg, CoordinatorStatus):
            self._coordinator_status(msg, item.stamp_s)

    def _assigned(self, a: Assignment, stamp_s: float) -> None:
        self.agent.on_assignment(a, stamp_s)
        self.sink.assignment(self.agent.assignment, stamp_s, self.agent.pose)

    def _coordinator_status(self, msg: CoordinatorStatus, stamp_s: float) -> None:
        held = self.leader.heard(msg)
        if held is not None:  # a new leader: its map, its last order
            self.need_merged = True
            if held.assignment is not None:
                self._assigned(held.assignment, stamp_s)
        have = -1 if self.agent.merged is None else self.agent.merged.version
        behind = msg.map_version > have
        self.behind_since = (self.behind_since or time.monotonic()) if behind else None
        if self.behind_since and time.monotonic() - self.behind_since > 1.0:
            self.need_merged, self.behind_since = True, None

    def _fetch_merged(self) -> None:
        got = self.bus.fetch_map(self.keys.merged_map, timeout_s=2.0)
        if got is None:
            return
        try:
            self.agent.on_merged_map(decode_map(got[0]))
            self.need_merged = False
        except DecodeError as e:
            log.warning("%s: bad merged map: %s", self.id, e)

    def process_scan(self, item) -> None:
        """One scan through the agent; its map update journaled, then everything sent."""
        agent = self.agent
        try:
            out = agent.on_scan(item.stamp_s, scan_from_message(item.msg, item.stamp_s))
        except PolyswarmError as e:
            log.warning("%s: scan %d refused: %s", agent.id, item.seq, e)
            agent.stats.refused += 1
            return
        wire = encode_delta(out.delta) if out.delta is not None else None
        if wire is not None and self.state_dir:
            self._journal(out.delta.version, wire)
        _send(self.bus, self.me, agent, out, item.stamp_s, item.seq, self.sink, wire)

    def _journal(self, version: int, wire: bytes) -> None:
        """On disk before anyone has seen it: a restart never reuses a published version."""
        agent = self.agent
        state = (agent.frame, agent.slam.odometry_scale, agent.own_frame)
        if agent.journaled == 0 or agent.journaled >= persist.SNAPSHOT_EVERY:
            persist.save_agent(
                self.state_dir, agent.id, agent.slam.map, agent.pose, agent.slam.odom, *state
            )
            agent.journaled = 1
        else:
            persist.journal_delta(
                self.state_dir, agent.id, wire, agent.pose, version, agent.slam.odom, *state
            )
            agent.journaled += 1

    def close(self) -> None:
        agent = self.agent
        if self.ros_node is not None:
            self.ros_node.close()
        agent.stats.refused += self.bus.rejected  # refused by the decoders on arrival
        self.bus.close()
        st = agent.stats
        log.info(
            "%s: %d scans, %d keyframes, %.1f m driven; returns kept from SLAM as other "
            "robots' %d, left out of ICP as blobs %d; messages refused %d",
            self.id,
            st.scans,
            st.keyframes,
            st.distance_m,
            st.peer_returns_masked,
            agent.slam.blob_returns_skipped,
            st.refused,
        )
        if self.state_dir:  # the map is on disk already (snapshot and journal): the pose
            persist.save_pose(
                self.state_dir,
                self.id,
                agent.pose,
                agent.slam.map.version,
                agent.slam.odom,
                agent.frame,
                agent.slam.odometry_scale,
                agent.own_frame,
            )


def _send(
    bus, me, agent: RobotAgent, out: Outbox, stamp_s: float, scan_seq: int, sink, wire=None
) -> None:
    """Send what ``out`` holds; ``wire`` is the delta already encoded (or None)."""
    if out.cmd is not None:
        sink.velocity(out.cmd[0], out.cmd[1], scan_seq, stamp_s)
    sent = 0
    if out.delta is not None:
        # a correction's poses, then the keyframe's merge when it is smaller than the
        # cells it changed (polyswarm.slam.follow, protocols.mapcodec.encode_updates)
        for what, base, ver, payload in encode_updates(out.delta, out.op, out.correction, wire):
            kind = MAP_KIND_OF[what]
            sent += bus.publish_map(me.map_delta, kind, payload, base, ver, stamp_s)
    if out.assignment is not None:
        sink.assignment(out.assignment, stamp_s, agent.pose)
    if out.pose is not None:
        sent += bus.publish(me.pose, out.pose, stamp_s)
    if out.status is not None:
        sent += bus.publish(me.status, out.status, stamp_s, reliable=True)
    agent.bytes_sent = bus.total_bytes_sent - bus.bytes_sent.get(me.cmd_vel, 0)
