"""Shared fixtures. Tests that read ../shared/data fail (never skip) when it is missing."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

from polyswarm.polymap import Ring, TypedPolygon, VectorType

settings.register_profile(
    "ci", max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.register_profile(  # HYPOTHESIS_PROFILE=thorough for a long local run
    "thorough", max_examples=600, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

np.set_printoptions(precision=17)  # failing examples must be reproducible from the report

O, F, S = VectorType.OBSTACLE, VectorType.FRONTIER, VectorType.SECTOR


@pytest.fixture(scope="session")
def shared_data() -> Path:
    from polyswarm.data import shared_data_dir

    return shared_data_dir()  # raises DataFormatError (a failure) if the folder is missing


def rect(x0, y0, x1, y1, types=(O, O, O, O)) -> TypedPolygon:
    """Axis-aligned rectangle, counter-clockwise from (x0, y0); types bottom, right, top, left."""
    return TypedPolygon(Ring([(x0, y0), (x1, y0), (x1, y1), (x0, y1)], list(types)))


def star(center, radii, types) -> TypedPolygon:
    """A star-shaped polygon around ``center`` with vertices at even angles."""
    n = len(radii)
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    xy = np.asarray(center) + np.stack([radii * np.cos(a), radii * np.sin(a)], axis=1)
    return TypedPolygon(Ring(xy, types))


def room_scan(t: float = 0.0):
    """A noise-free 270 degree scan from the centre of a 10 m square room (walls at
    x, y = +-5 m), facing +x."""
    from polyswarm.raycast import cast_rays
    from polyswarm.slam.scan import LaserScan

    corners = np.array([(-5.0, -5.0), (5.0, -5.0), (5.0, 5.0), (-5.0, 5.0)])
    angles = np.linspace(-2.35, 2.35, 361)
    r = cast_rays((0.0, 0.0), angles, corners, np.roll(corners, -1, axis=0), 30.0)
    return LaserScan(r.astype(np.float32), -2.35, angles[1] - angles[0], 0.1, 30.0, t)


# whole missions, benchmarks and real browsers: the full tier (`make test`, CI) runs
# them, the fast tier (`make check`) leaves them out
WHOLE_RUNS = {
    "test_launch_e2e",
    "test_netns",
    "test_faults",
    "test_unknown_start",
    "test_view",
    "test_examples",
    "test_fuzz",
    "test_bandwidth",
    "test_odomscale",
    "test_bench_cycle",
    "test_bench_explore",
    "test_bench_load",
    "test_bench_memory",
    "test_bench_merge",
}


# single tests over 10 s (pytest --durations): a whole recording or a long route each
LONG_TESTS = {
    "test_slam_following_the_graph_sends_corrections_a_receiver_and_the_coordinator_follow",
    "test_a_real_recording_played_into_ros2_is_mapped_by_the_agent_node",
    "test_an_anchored_slam_moves_its_map_as_one_correction_a_receiver_follows",
    "test_the_shared_turtlebot3_bag_maps_sharper_than_its_odometry",
    "test_slam_on_a_bag_uses_the_mount_from_tf_and_is_sharper_than_odometry",
    "test_replayed_log_builds_the_map_of_offline_slam",
}


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.stem in WHOLE_RUNS or item.originalname in LONG_TESTS:
            item.add_marker(pytest.mark.slow)


# --- a coordinator and its robots' maps ----------------------------------------------------


def corridor_map(open_end: bool):
    from polyswarm.polymap import GridPolyMap

    """A 12 m x 2 m corridor, its right end a frontier (or a wall)."""
    return GridPolyMap(2.0).merge(rect(0.0, 0.0, 12.0, 2.0, (O, F if open_end else O, O, O))).map


def coordinator(n: int = 2):
    """A coordinator of ``n`` robots, all alive, 1 m apart along y = 1."""
    from agents.coordinator import Coordinator
    from polyswarm.config import Config
    from protocols.messages import Pose

    starts = {f"r{k + 1}": (1.0 + k, 1.0, 0.0) for k in range(n)}
    c = Coordinator(Config(), starts)
    for rid, (x, y, _) in starts.items():
        c.on_alive(rid, True)
        c.on_pose(rid, 0.0, Pose(x, y, 0.0))
    return c


def feed(c, rid: str, pmap, t: float) -> None:
    """``pmap`` to the coordinator as robot ``rid``'s cell delta, through the codec."""
    from protocols.mapcodec import decode_delta, encode_delta

    base = c.robot(rid).map
    delta = pmap.delta_since(0 if base is None else base.version)
    c.on_robot_delta(rid, t, decode_delta(encode_delta(delta)))
