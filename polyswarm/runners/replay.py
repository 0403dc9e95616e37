"""``polyswarm agent --replay LOG``: a CARMEN log played into an agent over Zenoh.

A thread publishes the log's scans and odometry as the native polyswarm messages on the
robot's keys, as the simulator would, at ``rate`` times the log's own pace (0: as fast
as the agent keeps up). Odometry is built from the log's corrected poses with the
default noise model of ``polyswarm slam`` (the same seed gives the same odometry). The
player never gets more than ``MAX_UNACKED`` scans ahead of the agent's acknowledgements
(``CmdVel.ack``), so a slow machine slows the replay instead of dropping scans.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from pathlib import Path

import numpy as np

from polyswarm.io.carmen import read_carmen
from polyswarm.odometry import IncrementNoise, noisy_odometry
from protocols.keys import RobotKeys
from protocols.messages import CmdVel, Odometry, Scan

log = logging.getLogger(__name__)

MAX_UNACKED = 3  # scans published but not yet acknowledged by the agent
ACK_TIMEOUT_S = 10.0  # waiting longer than this for the agent: a warning, then go on


class LogPlayer:
    def __init__(self, path: str | Path, rate: float = 1.0, seed: int = 0, limit: int = 0) -> None:
        self.log = read_carmen(path)
        if limit > 0:  # the first ``limit`` scans only
            self.log = dataclasses.replace(self.log, scans=self.log.scans[:limit])
        self.rate = rate
        self.odom = noisy_odometry(self.log.reference, IncrementNoise(), seed)
        self.start_pose = tuple(float(v) for v in self.log.reference[0])
        self.published = 0
        self.done = threading.Event()
        self._acked = -1
        self._cv = threading.Condition()

    def on_ack(self, ack: int) -> None:
        with self._cv:
            if ack > self._acked:
                self._acked = ack
                self._cv.notify_all()

    def play(self, bus, me: RobotKeys, stop: threading.Event) -> None:
        """Publish every scan (odometry first); returns at the end or on ``stop``."""
        scans = self.log.scans
        t0_log, t0_wall = scans[0].stamp, time.monotonic()
        try:
            for k, s in enumerate(scans):
                if stop.is_set():
                    return
                if self.rate > 0:
                    wait = t0_wall + (s.stamp - t0_log) / self.rate - time.monotonic()
                    if wait > 0 and stop.wait(wait):
                        return
                with self._cv:
                    deadline = time.monotonic() + ACK_TIMEOUT_S
                    while k - self._acked > MAX_UNACKED and not stop.is_set():
                        if not self._cv.wait(timeout=0.2) and time.monotonic() > deadline:
                            log.warning("replay: no acknowledgement from the agent for 10 s")
                            break
                x, y, th = (float(v) for v in self.odom[k])
                bus.publish(me.odom, Odometry(x, y, th), s.stamp, reliable=True)
                sc = s.scan
                msg = Scan(
                    sc.angle_min,
                    sc.angle_increment,
                    sc.range_min,
                    sc.range_max,
                    np.asarray(sc.ranges, dtype=np.float32),
                )
                bus.publish(me.scan, msg, s.stamp, reliable=True)
                self.published = k + 1
            log.info("replay: all %d scans published", len(scans))
        finally:
            self.done.set()


def start_player(player: LogPlayer, session, me: RobotKeys, stop: threading.Event):
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
