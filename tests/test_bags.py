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
from protocols.bags import read_bag
from protocols.tf import mount_from_tf

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
    assert m["mount"] == "/tf_static" and m["scans"] == 200
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
    from tests.conftest import free_endpoint

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
    assert "mount from /tf_static: x 0.100 m, y 0.000 m, yaw 0.000 rad, upside down" in res.stdout
    # scan 5: the robot at (5.99, 3.16) heading +y (1.65 rad), the lidar 0.1 m ahead of
    # it: the wall y = 6 m is 2.83 m ahead along the heading
    assert "nearest return straight ahead: 2.83 m" in res.stdout
    assert out.stat().st_size > 1000


# --- bags as users record them --------------------------------------------------------------


def test_a_humble_rosbag2_without_message_definitions_opens_with_humbles(tmp_path):
    from polyswarm.benchmarks.bagmaker import without_definitions

    path = without_definitions(make_bag(tmp_path / "humble", "sqlite3", n_scans=30))
    bag = read_bag(path)  # Humble's definitions by default
    assert len(bag.scans) == 30 and bag.definitions == "ROS 2 humble's (the bag has none)"
    assert read_bag(path, ros_distro="jazzy").definitions.startswith("ROS 2 jazzy")
    with pytest.raises(DataFormatError, match="unknown ROS 2 distribution 'rolling'"):
        read_bag(path, ros_distro="rolling")


def test_a_mount_published_on_tf_is_found_beside_the_moving_odometry_transform(tmp_path):
    bag = read_bag(make_bag(tmp_path / "ros1_tf.bag", "ros1", n_scans=30, mount_topic="/tf"))
    assert bag.mounts.static is None
    m = bag.mount
    assert (m.x_m, m.y_m, m.yaw_rad, m.upside_down) == pytest.approx(MOUNT)


def test_two_mounts_that_disagree_are_named_and_tf_static_is_used(tmp_path, caplog):
    from polyswarm.config import LidarMount
    from protocols.tf import choose_mount

    bag = read_bag(make_bag(tmp_path / "two", "mcap", n_scans=30, tf_mount_error_m=0.1))
    assert bag.mounts.dynamic.x_m == pytest.approx(MOUNT[0] + 0.1)
    assert "/tf_static and /tf disagree" in bag.mounts.disagreement()
    mount, source = choose_mount(LidarMount(), bag.mounts, "two")
    assert source == "/tf_static" and mount.x_m == pytest.approx(MOUNT[0])
    assert "disagree on the lidar mount" in caplog.text


def test_the_raw_scan_topic_is_taken_by_the_stated_rule(tmp_path):
    from protocols.bags import pick_scan_topic

    bag = read_bag(
        make_bag(tmp_path / "two_scans", "mcap", n_scans=20, scan_copies=("/stable_scan",))
    )
    assert bag.scan_topic == "/scan" and "not from /stable_scan" in bag.scan_topic_note
    assert pick_scan_topic(["/robot1/scan", "/robot1/scan_filtered"])[0] == "/robot1/scan"
    assert pick_scan_topic(["/front", "/rear"])[0] is None  # no rule picks: the user must


def test_how_a_driver_reports_no_return_is_read_off_its_scans():
    import numpy as np

    from polyswarm.slam.scan import LaserScan
    from protocols.bags import no_return_convention

    def scan(values):
        return LaserScan(np.array(values, dtype=float), 0.0, 0.01, 0.1, 5.0)

    assert no_return_convention([scan([1.0, 0.0, 0.0, 2.0])]) == ("zero", 0.5)
    assert no_return_convention([scan([1.0, np.inf, np.nan, np.inf])]) == ("inf", 0.5)
    assert no_return_convention([scan([np.nan, 1.0, 1.0, 1.0])]) == ("nan", 0.25)
    assert no_return_convention([scan([1.0, 2.0])]) == ("inf", 0.0)


def test_a_mount_turned_by_pi_is_named_and_the_right_one_is_not(tmp_path):
    import numpy as np

    from polyswarm.slam.mountcheck import check_mount

    bag = read_bag(make_bag(tmp_path / "room", "mcap", n_scans=120))
    poses = np.array([[*o[1:]] for o in bag.odometry])
    right = check_mount(bag.scans, poses, MOUNT)
    x, y, yaw, flip = MOUNT
    wrong = check_mount(bag.scans, poses, (x, y, yaw + math.pi, flip))
    assert right.advice == ""
    assert "turned by pi" in wrong.advice and "check the mount" in wrong.advice
    assert wrong.cells["turned by pi"] == right.cells["as given"]


def test_slam_says_when_the_tf_mount_smears_the_map(tmp_path):
    bag = make_bag(tmp_path / "wrong_tf", "mcap", n_scans=120, mount_yaw_error_rad=math.pi)
    res = subprocess.run(
        [*CLI, "slam", str(bag), "-o", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert res.returncode == 0, res.stderr
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert "turned by pi" in metrics["mount_check"]["advice"]
    assert "check the mount" in res.stderr + res.stdout


def test_scans_and_odometry_from_different_times_give_one_clear_error(tmp_path):
    bag = make_bag(tmp_path / "late_odom", "mcap", n_scans=30, odom_shift_s=1000.0)
    res = subprocess.run(
        [*CLI, "slam", str(bag), "-o", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert res.returncode == 1
    assert "no scan lies within the odometry's time" in res.stderr
    assert "Traceback" not in res.stderr


def test_a_scan_topic_without_a_single_return_gives_one_clear_error(tmp_path):
    bag = make_bag(tmp_path / "blind", "mcap", n_scans=30, blind=True)
    res = subprocess.run(
        [*CLI, "slam", str(bag), "-o", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert res.returncode == 1
    assert "no sweep on /scan holds a valid return" in res.stderr
    assert "Traceback" not in res.stderr


def test_the_shared_real_bags_open_with_their_mounts_and_conventions(shared_data):
    office = read_bag(shared_data / "bags" / "neato-office-1.bag")
    assert office.scan_topic == "/scan" and "/stable_scan" in office.scan_topic_note
    assert office.mounts.static is None  # published on /tf, as ROS 1 setups do
    m = office.mount
    assert (m.x_m, m.yaw_rad) == pytest.approx((-0.1016, -math.pi), abs=1e-3)
    assert office.no_return == "zero" and office.no_return_share > 0.7
    square = read_bag(shared_data / "bags" / "neato-square.bag")
    assert "disagree" in square.mounts.disagreement()
    hokuyo = read_bag(shared_data / "bags" / "pioneer-hokuyo-corridor.bag")
    assert hokuyo.mount is None and hokuyo.no_return == "nan"
