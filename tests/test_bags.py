"""ROS bags in: every storage format, the mount from /tf_static, SLAM and agent replay."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from polyswarm.benchmarks.bagmaker import MOUNT, make_bag
from polyswarm.errors import DataFormatError
from protocols.bags import mount_from_tf, read_bag

CLI = [sys.executable, "-m", "polyswarm"]


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("bags")
    return {
        "mcap": make_bag(d / "room_mcap", "mcap"),
        "sqlite3": make_bag(d / "room_sqlite3", "sqlite3"),
        "ros1": make_bag(d / "room.bag", "ros1"),
    }


@pytest.mark.parametrize("kind", ["mcap", "sqlite3", "ros1"])
def test_every_storage_format_gives_the_scans_odometry_and_mount(bags, kind):
    bag = read_bag(bags[kind])
    assert len(bag.scans) == 200 and len(bag.odometry) == 200
    assert (bag.scan_topic, bag.odom_topic) == ("/scan", "/odom")
    assert bag.scans[0].angle_increment < 0  # clockwise beams, kept as the driver sent them
    m = bag.mount
    assert (m.x_m, m.y_m, m.yaw_rad, m.upside_down) == pytest.approx(MOUNT)
    assert (m.base_frame, m.scan_frame) == ("base_footprint", "laser")
    assert bag.ros2 == (kind != "ros1")
    assert not bag.skipped


def _tf(parent, child, xyz, quat):
    v = SimpleNamespace
    return v(
        header=v(frame_id=parent),
        child_frame_id=child,
        transform=v(
            translation=v(x=xyz[0], y=xyz[1], z=xyz[2]),
            rotation=v(x=quat[0], y=quat[1], z=quat[2], w=quat[3]),
        ),
    )


def test_mounts_you_can_work_out_by_hand():
    s = math.sqrt(0.5)
    yaw90 = SimpleNamespace(transforms=[_tf("base_link", "laser", (0.2, 0.1, 0.3), (0, 0, s, s))])
    m = mount_from_tf([yaw90], "base_link", "laser")
    assert (m.x_m, m.y_m, m.yaw_rad, m.upside_down) == pytest.approx((0.2, 0.1, math.pi / 2, False))
    # pitched by pi: upside down, its x axis backwards
    pitch = SimpleNamespace(transforms=[_tf("base_link", "laser", (0, 0, 0), (0, 1, 0, 0))])
    m = mount_from_tf([pitch], "base_link", "laser")
    assert m.upside_down and abs(abs(m.yaw_rad) - math.pi) < 1e-9
    # two hops, and base and laser under a common parent
    tree = SimpleNamespace(
        transforms=[
            _tf("base_footprint", "base_link", (0.5, 0, 0), (0, 0, 0, 1)),
            _tf("base_footprint", "laser", (0.7, 0.1, 0), (0, 0, 0, 1)),
        ]
    )
    m = mount_from_tf([tree], "base_link", "laser")
    assert (m.x_m, m.y_m, m.upside_down) == pytest.approx((0.2, 0.1, False))
    assert mount_from_tf([tree], "base_link", "camera") is None  # not connected


def _slam(bag: Path, out: Path, *extra: str) -> dict:
    res = subprocess.run(
        [*CLI, "slam", str(bag), "-o", str(out), *extra],
        capture_output=True,
        text=True,
        check=False,
    )
    assert res.returncode == 0, res.stderr
    return json.loads((out / "metrics.json").read_text())


def test_slam_on_a_bag_uses_the_mount_from_tf_and_is_sharper_than_odometry(bags, tmp_path):
    m = _slam(bags["mcap"], tmp_path / "tf")
    assert m["mount"] == "tf" and m["scans"] == 200
    assert m["occupied_cells_5cm"] < 0.5 * m["odometry_occupied_cells_5cm"]
    assert (tmp_path / "tf" / "map.polymap").exists()
    assert "upside_down = true" in (tmp_path / "tf" / "config.toml").read_text()
    # the same bag with a mount typed in wrongly (upright): the config wins, the map smears
    cfg = tmp_path / "upright.toml"
    cfg.write_text("[slam.mount]\nx_m = 0.1\n")
    wrong = _slam(bags["mcap"], tmp_path / "upright", "--config", str(cfg))
    assert wrong["mount"] == "config"
    assert wrong["occupied_cells_5cm"] > 1.5 * m["occupied_cells_5cm"]


def test_the_shared_turtlebot3_bag_maps_sharper_than_its_odometry(shared_data, tmp_path):
    m = _slam(shared_data / "bags" / "turtlebot3-gazebo.bag", tmp_path / "tb3")
    assert m["scans"] == 457 and m["mount"] == "default"  # the bag has no tf
    assert m["occupied_cells_5cm"] <= m["odometry_occupied_cells_5cm"]


def test_agent_replays_a_bag_over_zenoh_and_refuses_nothing(bags, tmp_path):
    from tests.test_ros_agent import free_endpoint

    out = tmp_path / "agent.polymap"
    args = ["agent", "--id", "r1", "--replay", str(bags["mcap"]), "--rate", "0"]
    args += ["--listen", free_endpoint(), "--out", str(out)]
    res = subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=300, check=False)
    assert res.returncode == 0, res.stderr
    assert "r1: 200 scans" in res.stderr and "0 messages refused" in res.stderr
    assert out.exists()


# --- bad bags -----------------------------------------------------------------------------


def test_a_wrong_topic_lists_the_bags_topics(bags):
    with pytest.raises(DataFormatError, match=r"no topic '/laser'.*/scan \(sensor_msgs"):
        read_bag(bags["mcap"], scan_topic="/laser")


def test_a_bag_without_odometry_says_so(tmp_path):
    from polyswarm.benchmarks.bagmaker import make_bag as make

    bag = make(tmp_path / "no_odom", "mcap", n_scans=20, topics=("/scan", "/tf_static"))
    with pytest.raises(DataFormatError, match="no nav_msgs/msg/Odometry topic"):
        read_bag(bag)


def test_truncated_and_corrupt_bags_give_one_clear_error_or_a_counted_skip(bags, tmp_path):
    whole = (bags["mcap"] / "room_mcap.mcap").read_bytes()
    for name, data in {
        "half": whole[: len(whole) // 2],
        "garbled": whole[:4000] + bytes(b ^ 0x5A for b in whole[4000:8000]) + whole[8000:],
        "empty": b"",
    }.items():
        path = tmp_path / f"{name}.mcap"
        path.write_bytes(data)
        try:
            bag = read_bag(path)
        except DataFormatError as e:
            assert str(path) in str(e)  # one line naming the bag
        else:
            assert len(bag.scans) < 200 or bag.skipped


def test_zero_beam_scans_and_repeated_stamps_are_skipped_and_counted(tmp_path):
    from polyswarm.benchmarks.bagmaker import make_bag as make

    bag = read_bag(make(tmp_path / "defects", "mcap", n_scans=50, defects=True))
    assert bag.skipped["unusable sensor_msgs/msg/LaserScan"] == 1
    assert bag.skipped["odometry with a repeated stamp"] == 1
    assert len(bag.scans) == 49
    stamps = [s.stamp for s in bag.scans]
    assert stamps == sorted(stamps)


def test_scan_command_prints_the_mount_and_what_is_straight_ahead(bags, tmp_path):
    out = tmp_path / "scan.png"
    res = subprocess.run(
        [*CLI, "scan", str(bags["ros1"]), "--index", "5", "-o", str(out)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert res.returncode == 0, res.stderr
    assert "mount from tf: x 0.100 m, y 0.000 m, yaw 0.000 rad, upside down" in res.stdout
    # scan 5: the robot at (5.99, 3.16) heading +y (1.65 rad), the lidar 0.1 m ahead of
    # it: the wall y = 6 m is 2.83 m ahead along the heading
    assert "nearest return straight ahead: 2.83 m" in res.stdout
    assert out.stat().st_size > 1000
