"""The Zenoh bus with real sessions on 127.0.0.1 (explicit endpoints, scouting off)."""

from __future__ import annotations

import socket
import time

import pytest

from agents.session import Bus, SessionSpec, is_alive_change, open_session, session_config
from polyswarm.errors import CommsError
from protocols.chunks import CHUNK_BYTES, MapChunk, MapKind
from protocols.keys import SwarmKeys
from protocols.messages import Clock, Odometry, Pose, encode

KEYS = SwarmKeys("test")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def endpoint():
    return f"tcp/127.0.0.1:{free_port()}"


def wait_for(bus: Bus, n: int, timeout_s: float = 5.0) -> list:
    got, deadline = [], time.monotonic() + timeout_s
    while len(got) < n and time.monotonic() < deadline:
        got += bus.poll(timeout_s=0.05)
    return got


def test_publish_subscribe_between_router_and_client(endpoint):
    with (
        open_session(SessionSpec.router(endpoint)) as rs,
        open_session(SessionSpec.client(endpoint)) as cs,
    ):
        router, client = Bus(rs, "coordinator"), Bus(cs, "r1")
        router.subscribe(KEYS.all_robots("pose"), Pose)
        time.sleep(0.3)
        for k in range(5):
            client.publish(KEYS.robot("r1").pose, Pose(k, 0, 0, map_version=k), stamp_s=k)
        got = wait_for(router, 5)
        assert [g.msg.x for g in got] == [0, 1, 2, 3, 4]
        assert [g.seq for g in got] == [0, 1, 2, 3, 4]
        assert {KEYS.robot_of(g.key) for g in got} == {"r1"}
        assert client.bytes_sent[KEYS.robot("r1").pose] > 0
        router.close()
        client.close()


def test_malformed_and_wrong_type_messages_are_counted_not_raised(endpoint):
    with (
        open_session(SessionSpec.router(endpoint)) as rs,
        open_session(SessionSpec.client(endpoint)) as cs,
    ):
        router = Bus(rs, "coordinator")
        router.subscribe(KEYS.robot("r1").odom, Odometry)
        time.sleep(0.3)
        key = KEYS.robot("r1").odom
        cs.put(key, b"\x00garbage")
        cs.put(key, encode(Clock(1.0), "r1", 0, 0.0))  # valid, but not odometry
        cs.put(key, encode(Odometry(1, 2, 3), "r1", 1, 0.0))
        got = wait_for(router, 1)
        assert [type(g.msg) for g in got] == [Odometry]
        assert router.rejected == 2
        router.close()


def test_large_map_is_chunked_and_reassembled_and_served_by_queryable(endpoint):
    payload = bytes(range(256)) * (3 * CHUNK_BYTES // 256 + 7)  # four chunks
    with (
        open_session(SessionSpec.router(endpoint)) as rs,
        open_session(SessionSpec.client(endpoint)) as cs,
    ):
        coord, robot = Bus(rs, "coordinator"), Bus(cs, "r1")
        coord.subscribe(KEYS.all_robots("map/delta"), MapChunk)
        robot.serve_map(KEYS.robot("r1").map, lambda: (payload, 12))
        time.sleep(0.3)
        sent = robot.publish_map(KEYS.robot("r1").map_delta, MapKind.DELTA, payload, 3, 4, 1.0)
        assert sent > len(payload)
        got = wait_for(coord, 1)
        assert len(got) == 1
        assert got[0].payload == payload and (got[0].msg.base, got[0].msg.ver) == (3, 4)
        fetched = coord.fetch_map(KEYS.robot("r1").map, timeout_s=5.0)
        assert fetched == (payload, 12)
        assert coord.fetch_map(KEYS.robot("r9").map, timeout_s=0.5) is None
        coord.close()
        robot.close()


def test_liveliness_reports_appearance_and_loss(endpoint):
    with open_session(SessionSpec.router(endpoint)) as rs:
        watcher = Bus(rs, "coordinator")
        watcher.watch_alive(KEYS.all_alive("agent"))
        with open_session(SessionSpec.client(endpoint)) as cs:
            agent = Bus(cs, "r1")
            agent.declare_alive(KEYS.alive("agent", "r1"))
            got = wait_for(watcher, 1)
            assert [is_alive_change(g) for g in got] == [True]
            assert KEYS.alive_name(got[0].key) == ("agent", "r1")
            agent.close()
        got = wait_for(watcher, 1)
        assert [is_alive_change(g) for g in got] == [False]
        watcher.close()


def test_session_config_has_scouting_off_and_bad_files_are_comms_errors(tmp_path):
    conf = session_config(SessionSpec.client("tcp/127.0.0.1:7447"))
    assert "false" in conf.get_json("scouting/multicast/enabled")
    with pytest.raises(CommsError, match="not found"):
        session_config(SessionSpec.client("", str(tmp_path / "missing.json5")))
    bad = tmp_path / "bad.json5"
    bad.write_text("{ mode: ")
    with pytest.raises(CommsError, match="invalid"):
        session_config(SessionSpec.client("", str(bad)))


def test_client_without_router_fails_with_comms_error_after_its_timeout():
    spec = SessionSpec.client(f"tcp/127.0.0.1:{free_port()}")
    t0 = time.monotonic()
    with pytest.raises(CommsError), open_session(spec, connect_timeout_s=0.5):
        pass
    assert time.monotonic() - t0 < 10
