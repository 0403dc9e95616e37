"""ROS 2 robots on rmw_zenoh, no bridge: keys, tokens and attachments as rmw_zenoh's
design document specifies them, and an agent driving such a robot over real Zenoh.

The examples are quoted from ros2/rmw_zenoh ``docs/design.md`` at commit
99a6a2bd10b949052f4f12c5854825dc005e95a5 (sections "Topic and Service name mapping to
Zenoh key expressions", "Graph Cache" and "Publishers"). ROS 2 cannot run here, so the
robot side of the live test is a Zenoh session speaking that format.
"""

from __future__ import annotations

import dataclasses
import threading
import time

import pytest

from agents.agent_node import run_agent
from agents.session import SessionSpec, open_session
from polyswarm.benchmarks.bagmaker import MOUNT, make_bag
from polyswarm.config import AgentIoConfig, Config
from protocols import rmw_zenoh as rz
from protocols import ros
from protocols.bags import read_bag
from protocols.messages import ProtocolError
from tests.conftest import free_endpoint

STRING = "std_msgs/msg/String"
CHATTER_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"


def test_topic_keys_of_the_design_document():
    assert rz.type_hash(STRING) == CHATTER_HASH
    assert (
        rz.topic_key(0, rz.qualified_name("", "chatter"), STRING)
        == f"0/chatter/std_msgs::msg::dds_::String_/{CHATTER_HASH}"
    )
    assert (
        rz.topic_key(0, rz.qualified_name("/robot1", "chatter"), STRING)
        == f"0/robot1/chatter/std_msgs::msg::dds_::String_/{CHATTER_HASH}"
    )


def test_liveliness_tokens_of_the_design_document():
    listener = "aac3178e146ba6f1fc6e6a4085e77f21"
    talker = "8b20917502ee955ac4476e0266340d5c"
    assert (
        rz.node_token(2, listener, 0, "", "listener")
        == f"@ros2_lv/2/{listener}/0/0/NN/%/%/listener"
    )
    assert rz.entity_token(2, listener, 0, 10, "MS", "", "listener", "/chatter", STRING) == (
        f"@ros2_lv/2/{listener}/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/"
        f"{CHATTER_HASH}/::,10:,:,:,,"
    )
    assert rz.entity_token(
        2, talker, 0, 10, "MP", "", "talker", "/chatter", STRING, qos=rz.qos_keyexpr(7)
    ) == (
        f"@ros2_lv/2/{talker}/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/"
        f"{CHATTER_HASH}/::,7:,:,:,,"
    )
    assert rz.mangle("/robot1") == "%robot1" and rz.mangle("") == "%"
    assert rz.node_token(0, listener, 0, "robot1", "n").endswith("/NN/%/%robot1/n")


def test_attachment_layout_of_the_design_document():
    gid = bytes(range(16))
    data = rz.encode_attachment(7, 1_700_000_000_123_456_789, gid)
    assert len(data) == 8 + 8 + 1 + 16
    assert data[:8] == (7).to_bytes(8, "little")
    assert data[8:16] == (1_700_000_000_123_456_789).to_bytes(8, "little")
    assert data[16] == 16 and data[17:] == gid
    assert rz.decode_attachment(data) == (7, 1_700_000_000_123_456_789, gid)
    for bad in (b"", data[:-1], data[:16] + b"\x08" + gid):
        with pytest.raises(ProtocolError):
            rz.decode_attachment(bad)


def test_agent_drives_an_rmw_zenoh_robot_and_reads_its_mount_from_tf(tmp_path):
    bag = read_bag(make_bag(tmp_path / "room", "mcap", n_scans=120))
    endpoint = free_endpoint()
    io = AgentIoConfig(source="rmw_zenoh", output="twist", namespace="tb3_1", domain_id=3)
    cfg = dataclasses.replace(Config(), agent=io)
    key = {
        t: rz.topic_key(3, f"/tb3_1/{name}", t)
        for name, t in (("scan", ros.LASER_SCAN), ("odom", ros.ODOMETRY))
    }
    tf_key = rz.topic_key(3, "/tb3_1/tf_static", ros.TF_MESSAGE)
    cmd_key = rz.topic_key(3, "/tb3_1/cmd_vel", ros.TWIST)
    twists: list[tuple[bytes, bytes]] = []
    stop = threading.Event()
    result = {}
    with open_session(SessionSpec.router(endpoint)) as robot:
        robot.declare_subscriber(
            cmd_key, lambda s: twists.append((s.payload.to_bytes(), s.attachment.to_bytes()))
        )
        agent_thread = threading.Thread(
            target=lambda: result.update(
                agent=run_agent("r1", cfg, bag.odometry[0, 1:], SessionSpec.client(endpoint), stop)
            )
        )
        agent_thread.start()
        time.sleep(1.5)
        gid = bytes(16)
        tf_raw = _tf_static_cdr()
        robot.put(tf_key, tf_raw, attachment=rz.encode_attachment(1, time.time_ns(), gid))
        k_odom = 0
        for k, scan in enumerate(bag.scans):
            while k_odom < len(bag.odometry) and bag.odometry[k_odom, 0] <= scan.end_stamp:
                robot.put(key[ros.ODOMETRY], bag.odom_raw[k_odom])
                k_odom += 1
            robot.put(key[ros.LASER_SCAN], bag.scan_raw[k])
            time.sleep(0.03)
        time.sleep(1.0)
        tokens = [str(r.ok.key_expr) for r in robot.liveliness().get("@ros2_lv/3/**")]
        stop.set()
        agent_thread.join(timeout=10)
    agent = result["agent"]
    assert agent.stats.scans >= 100 and agent.stats.refused == 0
    m = agent.cfg.slam.mount
    assert (m.x_m, m.y_m, m.yaw_rad, m.upside_down) == pytest.approx(MOUNT)
    assert twists, "no cmd_vel on the rmw_zenoh key"
    seqs = [rz.decode_attachment(a)[0] for _, a in twists]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    assert any("/NN/%/%tb3_1/polyswarm_agent_r1" in t for t in tokens)
    assert any(
        "/MS/" in t and "%tb3_1%scan/sensor_msgs::msg::dds_::LaserScan_/" in t for t in tokens
    )
    assert any(
        "/MP/" in t and "%tb3_1%cmd_vel/geometry_msgs::msg::dds_::Twist_/" in t for t in tokens
    )


def _tf_static_cdr() -> bytes:
    """The bag maker's tf (base_footprint -> base_link -> laser, upside down) as CDR."""
    ts = ros.typestore()
    T = ts.types

    def tr(parent, child, xyz, quat):
        return T["geometry_msgs/msg/TransformStamped"](
            header=T["std_msgs/msg/Header"](
                stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=parent
            ),
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=xyz[0], y=xyz[1], z=xyz[2]),
                rotation=T["geometry_msgs/msg/Quaternion"](
                    x=quat[0], y=quat[1], z=quat[2], w=quat[3]
                ),
            ),
        )

    msg = T[ros.TF_MESSAGE](
        transforms=[
            tr("base_footprint", "base_link", (0, 0, 0.05), (0, 0, 0, 1)),
            tr("base_link", "laser", (MOUNT[0], MOUNT[1], 0.2), (1, 0, 0, 0)),
        ]
    )
    return bytes(ts.serialize_cdr(msg, ros.TF_MESSAGE))
