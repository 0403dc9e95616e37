"""``polyswarm agent --replay LOG|BAG``: a CARMEN log or a ROS bag played into an agent
over Zenoh.

A thread publishes the recording's scans and odometry at ``rate`` times its own pace (0:
as fast as the agent keeps up):

* a CARMEN log (``LogPlayer``) as the native polyswarm messages on the robot's keys, as
  the simulator would, with odometry built from the log's corrected poses and the
  default noise model of ``polyswarm slam`` (the same seed gives the same odometry);
* a ROS bag (``BagPlayer``) as ROS 2 CDR on the agent's ROS keys, as
  zenoh-bridge-ros2dds would carry them from a robot: a rosbag2's messages byte for
  byte as recorded, a ROS 1 bag's converted. The agent decodes them as it would live.

The player never gets more than ``MAX_UNACKED`` scans ahead of the agent's
acknowledgements (``CmdVel.ack``), so a slow machine slows the replay instead of
dropping scans.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from pathlib import Path

import numpy as np

from polyswarm.config import AgentIoConfig
from polyswarm.io.carmen import read_carmen
from polyswarm.slam.odometry import IncrementNoise, noisy_odometry
from protocols.keys import RobotKeys
from protocols.messages import CmdVel, Odometry, Scan

log = logging.getLogger(__name__)

MAX_UNACKED = 3  # scans published but not yet acknowledged by the agent
ACK_TIMEOUT_S = 10.0  # waiting longer than this for the agent: a warning, then go on


class Player:
    """Paces a recording and waits for the agent's acknowledgements; a subclass says
    what to publish for scan ``k`` (``publish``) and when it was taken (``stamps``)."""

    def __init__(self, stamps: list[float], rate: float, start_pose) -> None:
        self.stamps = stamps
        self.rate = rate
        self.start_pose = tuple(float(v) for v in start_pose)
        self.published = 0
        self.done = threading.Event()
        self._acked = -1
        self._cv = threading.Condition()

    def on_ack(self, ack: int) -> None:
        with self._cv:
            if ack > self._acked:
                self._acked = ack
                self._cv.notify_all()

    def publish(self, bus, me: RobotKeys, k: int) -> None:
        raise NotImplementedError

    def play(self, bus, me: RobotKeys, stop: threading.Event) -> None:
        """Publish every scan (odometry first); returns at the end or on ``stop``."""
        t0_log, t0_wall = self.stamps[0], time.monotonic()
        try:
            for k, stamp in enumerate(self.stamps):
                if stop.is_set():
                    return
                if self.rate > 0:
                    wait = t0_wall + (stamp - t0_log) / self.rate - time.monotonic()
                    if wait > 0 and stop.wait(wait):
                        return
                with self._cv:
                    deadline = time.monotonic() + ACK_TIMEOUT_S
                    while k - self._acked > MAX_UNACKED and not stop.is_set():
                        if not self._cv.wait(timeout=0.2) and time.monotonic() > deadline:
                            log.warning("replay: no acknowledgement from the agent for 10 s")
                            break
                self.publish(bus, me, k)
                self.published = k + 1
            log.info("replay: all %d scans published", len(self.stamps))
        finally:
            self.done.set()


class LogPlayer(Player):
    def __init__(self, path: str | Path, rate: float = 1.0, seed: int = 0, limit: int = 0) -> None:
        self.log = read_carmen(path)
        if limit > 0:  # the first ``limit`` scans only
            self.log = dataclasses.replace(self.log, scans=self.log.scans[:limit])
        self.odom = noisy_odometry(self.log.reference, IncrementNoise(), seed)
        super().__init__([s.stamp for s in self.log.scans], rate, self.log.reference[0])

    def publish(self, bus, me: RobotKeys, k: int) -> None:
        s = self.log.scans[k]
        x, y, th = (float(v) for v in self.odom[k])
        bus.publish(me.odom, Odometry(x, y, th), s.stamp, reliable=True)
        bus.publish(me.scan, Scan.from_laserscan(s.scan), s.stamp, reliable=True)


class BagPlayer(Player):
    """A ROS bag's scans and odometry as ROS 2 CDR on ``io``'s keys (``source = "ros2"``);
    before each scan, the odometry up to the first reading after the scan's last beam."""

    def __init__(
        self,
        path: str | Path,
        io: AgentIoConfig,
        rate: float = 1.0,
        scan_topic: str | None = None,
        odom_topic: str | None = None,
    ) -> None:
        from protocols.bags import read_bag

        self.bag = read_bag(path, scan_topic, odom_topic)
        self.scan_key, self.odom_key = io.key(io.scan_key), io.key(io.odom_key)
        t = self.bag.odometry[:, 0]
        first = self.bag.scans[0].end_stamp
        start = self.bag.odometry[min(int(np.searchsorted(t, first)), len(t) - 1), 1:]
        super().__init__([s.stamp for s in self.bag.scans], rate, start)
        self._next_odom = 0

    def publish(self, bus, me: RobotKeys, k: int) -> None:
        from protocols import ros

        bag, scan = self.bag, self.bag.scans[k]
        odo = bag.odometry
        while self._next_odom < len(odo):
            t, x, y, th = odo[self._next_odom]
            raw = bag.odom_raw[self._next_odom] or ros.encode_odometry(t, (x, y, th))
            bus.put_raw(self.odom_key, raw, reliable=True)
            self._next_odom += 1
            if t >= scan.end_stamp:
                break
        raw = bag.scan_raw[k] or ros.encode_laserscan(scan, bag.scan_frame)
        bus.put_raw(self.scan_key, raw, reliable=True)


def start_player(player: Player, session, me: RobotKeys, stop: threading.Event):
    """Run ``player`` on its own thread with its own bus on ``session``."""
    from agents.session import Bus

    bus = Bus(session, "replay")

    def on_cmd(sample) -> None:
        from protocols.messages import decode

        try:
            _, msg = decode(sample.payload.to_bytes(), CmdVel)
            player.on_ack(msg.ack)
        except Exception:  # a malformed command only delays the replay
            log.debug("replay: bad command ignored")

    sub = session.declare_subscriber(me.cmd_vel, on_cmd)
    thread = threading.Thread(target=player.play, args=(bus, me, stop), daemon=True)
    thread.start()
    return thread, bus, sub
