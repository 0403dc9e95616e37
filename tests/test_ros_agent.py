"""Robot agents next to ROS 2: CDR messages over real Zenoh on loopback, log replay."""

from __future__ import annotations

import dataclasses
import threading
import time

import numpy as np
import pytest
import shapely

from agents.agent_node import run_agent
from agents.session import SessionSpec, open_session
from polyswarm.config import AgentIoConfig, Config
from polyswarm.runners.replay import LogPlayer, start_player
from polyswarm.slam.odometry import IncrementNoise, noisy_odometry
from polyswarm.slam.polyslam import PolySlam
from polyswarm.slam.scan import LaserScan
from protocols import ros
from protocols.keys import SwarmKeys
from protocols.messages import ProtocolError
from tests.conftest import free_endpoint


def test_cdr_round_trips_and_malformed_cdr_is_a_protocol_error():
    scan = LaserScan(np.array([1.0, np.inf, 2.5]), -0.5, 0.25, 0.1, 30.0, 12.25)
    back = ros.decode_laserscan(ros.encode_laserscan(scan))
    assert back.stamp == 12.25 and back.angle_increment == 0.25
    assert back.ranges[0] == 1.0 and np.isinf(back.ranges[1])
    stamp, pose, (v, w) = ros.decode_odometry(ros.encode_odometry(3.5, (1.0, -2.0, 2.0), 0.3, -0.1))
    assert stamp == 3.5 and np.allclose(pose, (1.0, -2.0, 2.0)) and (v, w) == (0.3, -0.1)
    assert ros.decode_twist(ros.encode_twist(0.25, -0.5)) == (0.25, -0.5)
    assert ros.decode_goal(ros.encode_goal((4.0, 5.0))) == (4.0, 5.0)
    good = ros.encode_laserscan(scan)
    for bad in (b"", b"\x00\x01\x00\x00", good[:20], good[:-7] + b"\xff" * 3):
        with pytest.raises(ProtocolError):
            ros.decode_laserscan(bad)
    wrong = LaserScan(np.array([1.0, 2.0]), 0.0, 0.0, 0.1, 30.0)  # zero increment
    with pytest.raises(ProtocolError):
        ros.decode_laserscan(ros.encode_laserscan(wrong))


def test_agent_maps_a_room_from_ros2_laserscan_and_odometry_over_zenoh():
    from sim import Simulation, load_world

    world = load_world("rooms")
    endpoint = free_endpoint()
    io = AgentIoConfig(source="ros2", output="twist", namespace="tb3_1")
    cfg = dataclasses.replace(Config(), agent=io)
    start = (1.5, 1.5, 0.0)
    stop = threading.Event()
    twists: list[tuple[float, float]] = []
    with open_session(SessionSpec.router(endpoint)) as session:
        session.declare_subscriber(
            "tb3_1/cmd_vel", lambda s: twists.append(ros.decode_twist(s.payload.to_bytes()))
        )
        result = {}
        agent_thread = threading.Thread(
            target=lambda: result.update(
                agent=run_agent("r1", cfg, start, SessionSpec.client(endpoint), stop)
            )
        )
        agent_thread.start()
        time.sleep(1.5)
        with Simulation(world, cfg.sim, 1, start_poses=[start]) as sim:
            sim.set_cmd(0, 0.0, 0.6)  # turn in place: the whole room comes into view
            sent = 0
            while sim.time < 12.0:
                for ev in sim.step():
                    x, y, th = ev.odom
                    session.put("tb3_1/odom", ros.encode_odometry(sim.time, (x, y, th)))
                    scan = dataclasses.replace(ev.scan, stamp=sim.time)
                    session.put("tb3_1/scan", ros.encode_laserscan(scan))
                    sent += 1
                    time.sleep(0.01)
        time.sleep(1.0)
        replies = list(session.get(SwarmKeys("default").robot("r1").map, timeout=5.0))
        stop.set()
        agent_thread.join(timeout=10)
    agent = result["agent"]
    assert agent.stats.scans >= 0.9 * sent
    assert agent.stats.keyframes >= 5
    explored = agent.slam.map.explored_region()
    inside = shapely.intersection(explored, world.free.buffer(0.05)).area / explored.area
    assert explored.area > 15.0 and inside > 0.97  # the first room, not beyond its walls
    assert replies, "the agent's map queryable answered nothing"
    assert twists and all(abs(v) <= 0.5 and abs(w) <= 2.0 for v, w in twists)


def test_replayed_log_builds_the_map_of_offline_slam(shared_data):
    path = shared_data / "logs" / "aces-corrected.log.gz"
    player = LogPlayer(path, rate=0.0, limit=120)
    endpoint = free_endpoint()
    cfg = Config()
    stop = threading.Event()

    def attach(session, agent, stop_event):
        _, bus, sub = start_player(player, session, SwarmKeys("default").robot("r1"), stop_event)

        def finish():
            player.done.wait(120)
            for _ in range(200):
                if agent.stats.scans >= player.published:
                    break
                time.sleep(0.05)
            stop_event.set()

        threading.Thread(target=finish, daemon=True).start()
        return lambda: (sub.undeclare(), bus.close())

    agent = run_agent(
        "r1", cfg, player.start_pose, SessionSpec.router(endpoint), stop, attach=attach
    )
    assert agent.stats.scans == 120
    # offline PolySLAM over the same scans (at the wire's float32 precision: on this log
    # PolySLAM is sensitive to 1e-7 relative changes of the ranges) and odometry
    ref = player.log.reference
    odom = noisy_odometry(ref, IncrementNoise(), 0)
    slam = PolySlam(cfg.slam, cfg.map.cell_size_m, initial_pose=ref[0])
    for k, s in enumerate(player.log.scans):
        f32 = np.asarray(s.scan.ranges, dtype=np.float32).astype(float)
        slam.process(dataclasses.replace(s.scan, ranges=f32), odom[k])
    a, b = agent.slam.map.explored_region(), slam.map.explored_region()
    iou = shapely.intersection(a, b).area / shapely.union(a, b).area
    assert iou > 0.99
    assert np.allclose(agent.pose, slam.pose, atol=0.01)
