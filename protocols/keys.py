"""Zenoh key expressions of a swarm (PROTOCOL.md section 5.1).

keys = SwarmKeys("lab")
keys.robot("r1").scan          # polyswarm/lab/robots/r1/scan
keys.all_robots("map/delta")   # polyswarm/lab/robots/*/map/delta
keys.robot_of(key)             # "r1" for any key under robots/r1/
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from polyswarm.errors import ConfigError

ROOT = "polyswarm"
NAME_RE = re.compile(r"^[A-Za-z0-9_-]{1,32}$")  # swarm and robot names: one key chunk


def check_name(name: str, what: str = "name") -> str:
    """A swarm or robot name must be one key chunk of letters, digits, '_' or '-'."""
    if not isinstance(name, str) or not NAME_RE.match(name):
        raise ConfigError(
            f"{what} {name!r} must be 1-32 letters, digits, '_' or '-' (it is a key chunk)"
        )
    return name


@dataclass(frozen=True)
class RobotKeys:
    base: str

    @property
    def scan(self) -> str:
        return f"{self.base}/scan"

    @property
    def odom(self) -> str:
        return f"{self.base}/odom"

    @property
    def cmd_vel(self) -> str:
        return f"{self.base}/cmd_vel"

    @property
    def pose(self) -> str:
        return f"{self.base}/pose"

    @property
    def map_delta(self) -> str:
        return f"{self.base}/map/delta"

    @property
    def map(self) -> str:
        """Queryable: the robot's full map, as map chunks."""
        return f"{self.base}/map"

    @property
    def status(self) -> str:
        return f"{self.base}/status"


@dataclass(frozen=True)
class SwarmKeys:
    swarm: str

    def __post_init__(self) -> None:
        check_name(self.swarm, "swarm name")

    @property
    def prefix(self) -> str:
        return f"{ROOT}/{self.swarm}"

    def robot(self, robot_id: str) -> RobotKeys:
        return RobotKeys(f"{self.prefix}/robots/{check_name(robot_id, 'robot id')}")

    def all_robots(self, suffix: str) -> str:
        return f"{self.prefix}/robots/*/{suffix}"

    def robot_of(self, key: str) -> str | None:
        """The robot id of a key under ``robots/<id>/``, else None."""
        head = f"{self.prefix}/robots/"
        if not key.startswith(head):
            return None
        rid = key[len(head) :].split("/", 1)[0]
        return rid if NAME_RE.match(rid) else None

    # coordinator
    def assignment(self, robot_id: str) -> str:
        return f"{self.prefix}/coordinator/assignment/{check_name(robot_id, 'robot id')}"

    @property
    def all_assignments(self) -> str:
        return f"{self.prefix}/coordinator/assignment/*"

    def anchor(self, robot_id: str) -> str:
        return f"{self.prefix}/coordinator/anchor/{check_name(robot_id, 'robot id')}"

    @property
    def all_anchors(self) -> str:
        return f"{self.prefix}/coordinator/anchor/*"

    def priors(self, robot_id: str) -> str:
        return f"{self.prefix}/coordinator/priors/{check_name(robot_id, 'robot id')}"

    @property
    def merged_delta(self) -> str:
        return f"{self.prefix}/coordinator/map/delta"

    @property
    def merged_map(self) -> str:
        """Queryable: the merged map, as map chunks."""
        return f"{self.prefix}/coordinator/map"

    @property
    def coordinator_status(self) -> str:
        return f"{self.prefix}/coordinator/status"

    # simulation (absent on real robots)
    @property
    def clock(self) -> str:
        return f"{self.prefix}/sim/clock"

    @property
    def truth(self) -> str:
        """Ground-truth poses: for metrics only, never read by agents or coordinator."""
        return f"{self.prefix}/sim/truth"

    # liveliness tokens, one per process
    def alive(self, role: str, name: str) -> str:
        return f"{self.prefix}/alive/{check_name(role, 'role')}/{check_name(name)}"

    def all_alive(self, role: str = "*") -> str:
        return f"{self.prefix}/alive/{role}/*"

    def alive_name(self, key: str) -> tuple[str, str] | None:
        """(role, name) of a liveliness key, else None."""
        head = f"{self.prefix}/alive/"
        if not key.startswith(head):
            return None
        parts = key[len(head) :].split("/")
        if len(parts) != 2 or not all(NAME_RE.match(p) for p in parts):
            return None
        return parts[0], parts[1]
