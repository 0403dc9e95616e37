"""Shared fixtures. Tests that read ../shared/data fail (never skip) when it is missing."""

from __future__ import annotations

import os
import threading
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

from polyswarm.polymap import MergeOptions, Ring, TypedPolygon, VectorType

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


# --- a building, mapped by robots in frames of their own (map matching) --------------------

CELL_M = 2.0


def building():
    import shapely
    from shapely.geometry import box

    """A corridor with rooms of different sizes off it, a pillar in one: no symmetry."""
    parts = [
        box(0, 0, 24, 2),  # corridor
        box(1, 2, 5, 7),
        box(6, 2, 9, 5),
        box(11, 2, 17, 8),
        box(19, 2, 23, 4),
        box(2, -6, 8, 0),
        box(13, -3, 15, 0),
        box(17, -7, 23, 0),
    ]
    doors_closed = shapely.union_all(parts)
    return shapely.difference(doors_closed, box(19, -5, 20, -4))  # the pillar


def typed_regions(region, walls) -> list[TypedPolygon]:
    import shapely
    import shapely.geometry

    """Typed polygons of ``region``: edges on ``walls`` are obstacles, others frontiers."""
    out = []
    polys = [g for g in getattr(region, "geoms", [region]) if g.geom_type == "Polygon"]
    for piece in polys:
        p = shapely.geometry.polygon.orient(piece, 1.0)  # shell ccw, holes clockwise
        rings = []
        for ring in [p.exterior, *p.interiors]:
            xy = np.asarray(ring.coords)[:-1]
            mids = 0.5 * (xy + np.roll(xy, -1, axis=0))
            on_wall = shapely.distance(walls, shapely.points(mids)) < 1e-6
            types = np.where(on_wall, VectorType.OBSTACLE, VectorType.FRONTIER)
            rings.append(Ring(xy, types))
        out.append(TypedPolygon(rings[0], tuple(rings[1:])))
    return out


def seen_map(window, pose=(0.0, 0.0, 0.0)):
    import shapely

    from polyswarm.frames.mapmatch import transform_map
    from polyswarm.polymap import GridPolyMap
    from polyswarm.se2 import inverse

    """The part of the building inside ``window``, as a robot whose frame is ``pose`` (in
    the building's frame) would have mapped it."""
    b = building()
    part = shapely.intersection(b, window)
    m = GridPolyMap.from_polygons(typed_regions(part, b.boundary), CELL_M)
    return transform_map(m, inverse(np.asarray(pose, dtype=float)))


def profile_with_a_robot_at(xy, clear_m: float = 10.0) -> bytes:
    """A clear profile: clear to ``clear_m`` all around, and a robot's body at ``xy``
    (metres, the viewer's frame)."""
    from polyswarm.frames.sighting import BODY_M, CLEAR_UNIT_M, SECTORS, _sector

    out = [int(clear_m / CLEAR_UNIT_M)] * SECTORS
    d = float(np.hypot(*xy)) - BODY_M / 2
    out[int(_sector(np.arctan2(xy[1], xy[0])))] = int(d / CLEAR_UNIT_M)
    return bytes(out)


# --- robot merges replayed (a corridor and side rooms) --------------------------------------

REPLAY_OPTS = MergeOptions(0.05, 0.05, 0.01, 0.1, 0.08)
# keyframe polygons of a robot driving along a corridor and into side rooms
RECTS = [
    (-0.5, -0.5, 3.3, 0.7, (O, F, O, F)),
    (3.0, -0.5, 5.1, 0.7, (O, F, O, O)),
    (4.2, 0.6, 4.9, 2.5, (O, O, O, F)),
    (-0.4, 0.6, 0.4, 2.5, (O, O, F, O)),
    (4.0, 2.4, 7.5, 4.1, (O, F, O, F)),
]


def shifted(r, dy: float):
    x0, y0, x1, y1, types = r
    return rect(x0, y0 + dy, x1, y1 + dy, types)


def ops_of(polys):
    from polyswarm.polymap import GridPolyMap, MergeOp, cells_digest

    """A robot's map after merging ``polys``, and the merges it sent."""
    pmap, ops = GridPolyMap(2.0), []
    for poly in polys:
        res = pmap.merge(poly, REPLAY_OPTS)
        digest = cells_digest(res.map.cells[i] for i in res.changed)
        ops.append(MergeOp(2.0, pmap.version, res.map.version, poly, REPLAY_OPTS, digest))
        pmap = res.map
    return pmap, ops


def same(a, b) -> bool:
    from polyswarm.polymap import cells_digest

    return a.version == b.version and cells_digest(a.cells.values()) == cells_digest(
        b.cells.values()
    )


# --- launches and sessions ---------------------------------------------------------------


def assert_nothing_lost(out) -> None:
    """The coordinator's merged map holds everything it received from each robot, and
    each robot still holds everything it sent (deltas in flight at shutdown are in the
    robot's own persisted map)."""
    from polyswarm.benchmarks.faults import lost_space

    lost = lost_space(out)
    assert set(lost) == {"r1", "r2"}
    for r, v in lost.items():
        assert v["missing_m2"] <= 1e-3 * v["shared_m2"], f"{v} of {r} not in the merge"
        assert v["dropped_m2"] <= 1e-3 * v["shared_m2"], f"{r} lost what it had sent: {v}"


def kill_by_pid(out, name: str) -> int:
    """SIGKILL process ``name`` of the launch writing to ``out`` by its process id
    (``logs/pids.json``), as the kernel's out-of-memory killer would: not through
    launch's fault injection. Returns the id."""
    import json
    import os
    import signal

    pid = json.loads((out / "logs" / "pids.json").read_text())[name]
    os.kill(pid, signal.SIGKILL)
    return pid


def free_endpoint() -> str:
    """A TCP endpoint on 127.0.0.1 no one listens on (yet)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


# --- a room with a pillar, scanned (ICP and the pose graph) ---------------------------------

ANGLES = np.linspace(-2.35, 2.35, 720)


def room():
    """A 6 m x 4 m room (counter-clockwise: free inside) with a pillar (clockwise), as
    vectors (starts, ends)."""
    outer = np.array([[0, 0], [6, 0], [6, 4], [0, 4]], float)
    pillar = np.array([[2, 2.5], [2, 3], [2.5, 3], [2.5, 2.5]], float)
    s = np.vstack([outer, pillar])
    e = np.vstack([np.roll(outer, -1, 0), np.roll(pillar, -1, 0)])
    return s, e


def scan_at(pose, s, e, sigma=0.01, seed=0):
    """A 720-beam scan's points (sensor frame) at ``pose`` among vectors ``s``-``e``,
    noise ``sigma`` metres."""
    from polyswarm.raycast import cast_rays

    r = cast_rays(pose[:2], ANGLES + pose[2], s, e, 30.0)
    r = r + np.random.default_rng(seed).normal(0, sigma, len(r))
    ok = np.isfinite(r)
    return np.stack([r[ok] * np.cos(ANGLES[ok]), r[ok] * np.sin(ANGLES[ok])], 1)


# --- PolyMap checks ----------------------------------------------------------------------


def total_length(pmap, kind) -> float:
    """Length of the map's vectors of type ``kind``, metres."""
    s, e, _ = pmap.vectors([kind])
    return float(np.hypot(*(e - s).T).sum())


def assert_well_formed(pmap) -> None:
    """Every cell: valid polygons inside the cell, free space on the left of every vector."""
    import shapely

    from polyswarm.polymap import PRECISION_M

    for cell in pmap.cells.values():
        assert cell.region.is_valid
        x0, y0, x1, y1 = cell.bounds
        bx = cell.region.bounds
        assert (
            bx[0] >= x0 - 1e-9 and bx[1] >= y0 - 1e-9 and bx[2] <= x1 + 1e-9 and bx[3] <= y1 + 1e-9
        )
        for poly in cell.polygons:
            assert poly.shell.signed_area > 0
            assert all(h.signed_area < 0 for h in poly.holes)
            for ring in poly.rings():
                # vertices on the 1 mm grid
                assert np.allclose(ring.xy, np.rint(ring.xy / PRECISION_M) * PRECISION_M, atol=1e-9)
                # a point just left of each vector's midpoint is explored
                a, b = ring.segments()
                d = b - a
                L = np.hypot(d[:, 0], d[:, 1])
                left = 0.5 * (a + b) + 1e-7 * np.stack([-d[:, 1], d[:, 0]], axis=1) / L[:, None]
                assert shapely.intersects_xy(cell.region, left[:, 0], left[:, 1]).all()


# --- robots in frames of their own (anchoring) ---------------------------------------------


def anchoring_ticks(frames, main, now: float, until, wall_s: float = 120.0) -> tuple[list, float]:
    """``frames.tick`` once a simulated second until ``until()``; what it sent, and now."""
    import time

    sent, give_up = [], time.monotonic() + wall_s
    while not until() and time.monotonic() < give_up:
        sent += frames.tick(main, now)
        now += 1.0
        time.sleep(0.02)
    return sent, now


# --- a real ROS 2 graph (rclpy and Fast DDS from PyPI) ------------------------------------


@contextmanager
def rclpy_node(domain: int, name: str, namespace: str):
    """A real rclpy node on DDS domain ``domain``, spun on a thread of its own."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node(name, namespace=namespace, context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    try:
        yield node
    finally:
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        ctx.shutdown()


@contextmanager
def agent_on_a_thread(rid: str, cfg, start_pose):
    """``run_agent`` on a thread, beside a Zenoh router of its own: yields a dict that
    holds the agent (``"agent"``) once it returned; stopped and joined on exit."""
    from agents.agent_node import run_agent
    from agents.session import SessionSpec, open_session

    endpoint, stop, result = free_endpoint(), threading.Event(), {}
    with open_session(SessionSpec.router(endpoint)):
        client = SessionSpec.client(endpoint)
        thread = threading.Thread(
            target=lambda: result.update(agent=run_agent(rid, cfg, start_pose, client, stop))
        )
        thread.start()
        try:
            yield result
        finally:
            stop.set()
            thread.join(timeout=20)
