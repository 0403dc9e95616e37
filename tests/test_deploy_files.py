"""The deployment files in agents/deploy load as they are documented."""

from __future__ import annotations

from pathlib import Path

import pytest
import zenoh

from polyswarm.config import load_config

DEPLOY = Path(__file__).resolve().parents[1] / "agents" / "deploy"


@pytest.mark.parametrize("name", ["robot.toml", "coordinator.toml"])
def test_toml_configs_load(name):
    cfg = load_config(DEPLOY / name)
    assert cfg.comms.swarm == "lab"
    assert cfg.robots and cfg.robots[0].id == "r1"


def test_robot_config_reads_ros2_topics_of_its_namespace():
    cfg = load_config(DEPLOY / "robot.toml")
    assert cfg.agent.key(cfg.agent.scan_key) == "tb3_1/scan"
    assert cfg.agent.key(cfg.agent.cmd_vel_key) == "tb3_1/cmd_vel"


@pytest.mark.parametrize("path", sorted(DEPLOY.glob("*.json5")), ids=lambda p: p.name)
def test_zenoh_configs_parse(path):
    conf = zenoh.Config.from_file(str(path))
    assert "false" in conf.get_json("scouting/multicast/enabled")


def test_fleet_router_has_one_acl_rule_per_robot():
    conf = zenoh.Config.from_file(str(DEPLOY / "zenoh-fleet-router.json5"))
    rules = conf.get_json("access_control/rules")
    assert all(f'"own-r{k}"' in rules for k in (1, 2, 3))
    assert '"deny"' in conf.get_json("access_control/default_permission")


def test_systemd_unit_runs_the_agent():
    unit = (DEPLOY / "polyswarm-agent.service").read_text()
    assert "ExecStart=" in unit and "polyswarm agent --id" in unit and "[Install]" in unit
