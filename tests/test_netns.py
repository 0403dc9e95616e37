"""A fleet on separate network stacks (``launch --netns``): real namespaces, veths and a
bridge made with ``ip``, links cut from outside the processes. Needs root."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest

from polyswarm.runners import netns

pytestmark = pytest.mark.skipif(
    os.geteuid() != 0 or shutil.which("ip") is None, reason="needs root and iproute2"
)


def _ours(run: str) -> list[str]:
    return [n for n in netns.namespaces() if n.startswith(f"{netns.PREFIX}{run}-")]


def _in(ns: str, code: str) -> subprocess.CompletedProcess:
    cmd = ["ip", "netns", "exec", ns, sys.executable, "-c", code]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=30, check=False)


def test_hosts_reach_each_other_over_wifi0_only_and_a_cut_link_is_cut(tmp_path):
    run = "t" + os.urandom(1).hex()
    net = netns.FleetNetwork.create(run, ["a", "b"], tmp_path / "sockets")
    try:
        assert sorted(_ours(run)) == [net.namespace("a"), net.namespace("b")]
        server = (
            "import socket; s = socket.socket(); "
            f"s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1); "
            f"s.bind(('{net.address('b')}', 9000)); s.listen(); s.settimeout(20); "
            "c, _ = s.accept(); c.sendall(b'hello'); c.close()"
        )
        client = (
            "import socket; s = socket.create_connection"
            f"(('{net.address('b')}', 9000), timeout=3); print(s.recv(5).decode())"
        )
        srv = subprocess.Popen(
            ["ip", "netns", "exec", net.namespace("b"), sys.executable, "-c", server]
        )
        time.sleep(0.5)
        assert _in(net.namespace("a"), client).stdout.strip() == "hello"
        srv.wait(timeout=10)
        # the launch's own network cannot reach a host: it lives in a stack of its own
        assert (
            _in(
                net.namespace("a"), "import socket; socket.create_connection(('127.0.0.1', 1), 1)"
            ).returncode
            != 0
        )
        net.cut("b")
        cut = _in(net.namespace("a"), client)
        assert cut.returncode != 0 and "hello" not in cut.stdout
    finally:
        net.remove()
    assert _ours(run) == []


def test_a_network_whose_launch_died_is_swept_away_by_the_next(tmp_path):
    run = "t" + os.urandom(1).hex()
    net = netns.FleetNetwork.create(run, ["a", "b"], tmp_path / "sockets")
    try:
        dead = subprocess.Popen(["true"])
        dead.wait()
        netns._owner(run).write_text(str(dead.pid))  # its launch was killed (SIGKILL)
        assert sorted(netns.sweep_stale()) == sorted([net.namespace("a"), net.namespace("b")])
        assert _ours(run) == [] and not netns._owner(run).exists()
    finally:
        net.remove()


def test_without_root_netns_says_so_in_one_line(monkeypatch):
    monkeypatch.setattr(netns.os, "geteuid", lambda: 1000)
    with pytest.raises(netns.NetworkError, match="needs root"):
        netns.check_can_build()


def test_cutting_a_link_without_netns_is_a_one_line_error(tmp_path):
    cmd = [sys.executable, "-m", "polyswarm", "launch", "--robots", "1", "--world", "rooms"]
    cmd += ["--fault", "cut:r1@5", "--out", str(tmp_path / "run")]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines()[-1].startswith("error: fault")


def _office_launch(tmp_path, faults: str, coordinators: int = 1) -> tuple[dict, object]:
    """3 robots on the office with --netns and ``faults``; (metrics, run folder) of a
    launch that exited 0."""
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "polyswarm", "launch", "--robots", "3", "--world", "office"]
    cmd += ["--speed", "0", "--wall-limit", "400", "--netns", "--out", str(out)]
    cmd += ["--coordinators", str(coordinators), "--fault", faults]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=500, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads((out / "metrics.json").read_text()), out


def test_robots_cut_off_keep_mapping_and_their_maps_agree_with_the_coordinators_after(tmp_path):
    """Three robots on the office, each agent and the coordinator in a namespace of its
    own; r1 out of range from 30 to 90 simulated seconds, r2 from 50 to 110. Measured:
    100 % coverage at t99 134 s; exploring frontiers of their own maps while cut, r1
    made 65 and r2 59 keyframes (15 and 10 when they stood at their last target); every
    map the coordinator holds the same version as the robot's own at the end."""
    m, out = _office_launch(tmp_path, "cut:r1@30,restore:r1@90,cut:r2@50,restore:r2@110")
    run = json.loads((out / "logs" / "netns.json").read_text())["run"]
    assert _ours(run) == []  # namespaces, links and bridge gone
    assert m["final_coverage"] >= 0.99 and m["map_iou"] >= 0.95, m["final_coverage"]
    outages = {o["robot"]: o for o in m["link_outages"]}
    for rid in ("r1", "r2"):
        o = outages[rid]
        assert o["rejoined_s"] is not None, o  # heard again after the restore
        assert o["keyframes_at_rejoin"] > o["keyframes_at_cut"], o  # kept mapping while cut
    assert all(v["agree"] for v in m["maps_agree"].values()), m["maps_agree"]


def test_a_standby_takes_over_when_the_active_coordinators_host_is_lost(tmp_path):
    """Two coordinators on hosts of their own; at 40 simulated seconds the active one's
    host is gone (its processes killed, its link down). Measured: coordinator2 took
    over 5.7 s later (wall), the robots followed it and the mission ended at 100 %."""
    m, _ = _office_launch(tmp_path, "kill:coordinator@40,cut:coordinator@40", coordinators=2)
    assert m["mission_state"] == "done" and m["final_coverage"] >= 0.99, m["stopped_because"]
    assert [(t, n) for t, n, *_ in m["leaders"]] == [(0, "coordinator"), (1, "coordinator2")]
    assert len(m["takeover_s"]) == 1 and m["takeover_s"][0] <= 10.0, m["takeover_s"]
    assert m["crashed_processes"] == []


def test_an_active_coordinator_cut_off_stands_by_for_the_one_that_took_over(tmp_path):
    """A split brain that heals: the active coordinator's host out of range from 40 to 80
    simulated seconds (its processes run on); coordinator2 takes over at term 1. Back in
    range, the first hears an active coordinator of a higher term and stands by; the
    robots follow coordinator2 throughout. Measured: taken over at 58 s, mission done at
    100 %, every map copy equal to its robot's."""
    m, out = _office_launch(tmp_path, "cut:coordinator@40,restore:coordinator@80", 2)
    assert m["mission_state"] == "done" and m["final_coverage"] >= 0.99, m["stopped_because"]
    assert [(t, n) for t, n, *_ in m["leaders"]] == [(0, "coordinator"), (1, "coordinator2")]
    first = " ".join((out / "logs" / "coordinator.log").read_text().split())
    assert "coordinator2 (term 1) is active: standing by" in first
    assert all(v["agree"] for v in m["maps_agree"].values()), m["maps_agree"]
    assert m["crashed_processes"] == []


def test_ctrl_c_removes_the_network(tmp_path):
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "polyswarm", "launch", "--robots", "2", "--world", "office"]
    cmd += ["--speed", "0", "--netns", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    meta = out / "logs" / "netns.json"
    deadline = time.monotonic() + 60
    while not meta.exists() and time.monotonic() < deadline:
        time.sleep(0.2)
    run = json.loads(meta.read_text())["run"]
    time.sleep(5)
    assert len(_ours(run)) == 3  # coordinator, r1, r2
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=120)
    assert _ours(run) == []


def test_bench_fleet_compares_one_stack_with_namespaces_side_by_side(tmp_path):
    from polyswarm.benchmarks import fleet

    res = fleet.run((2,), "rooms", 60.0, tmp_path)
    one, mesh = res["runs"]
    assert (one["netns"], mesh["netns"]) == (False, True)
    assert one["final_coverage"] >= 0.95 and mesh["final_coverage"] >= 0.95
    assert mesh["maps_agree"] is True and one["maps_agree"] is None
    ratio = res["bytes_per_robot_ratio_netns_vs_loopback"]["2"]
    assert ratio == mesh["bytes_per_robot_per_sim_s"] / one["bytes_per_robot_per_sim_s"]
    assert 0.5 < ratio < 2.0  # the same messages, over a mesh of routers
