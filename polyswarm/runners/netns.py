"""A fleet on separate network stacks: one Linux network namespace per host.

``polyswarm launch --netns`` runs each robot's agent and the coordinator in a namespace
of its own (``ps-<run>-r1``, ``ps-<run>-coordinator``), as on separate computers. Each
host's only link to the others is a veth named ``wifi0`` inside its namespace, joined to
one bridge (the radio); cutting it (``ip link set wifi0 down``, ``cut``) is a robot
out of range, from outside its processes. Each host's process is its own Zenoh router:
it listens on its ``wifi0`` address and connects to the hosts before it, so the routers
form a mesh (Zenoh's own routing), not a star through one process.

The simulator stands for the robots' own sensors and the launch's observer for a
test harness: they reach the hosts over Unix sockets (``unix_endpoint``), which no
network namespace separates and no cut touches.

    net = FleetNetwork.create("ab12", ["coordinator", "r1", "r2"], sockets_dir)
    net.wrap("r1")          # ["ip", "netns", "exec", "ps-ab12-r1"]: prefix of its command
    net.cut("r1"); net.restore("r1")
    net.remove()            # namespaces, links and the bridge gone

Needs root (``CAP_NET_ADMIN``) and ``ip`` from iproute2; ``NetworkError`` otherwise.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

from polyswarm.errors import PolyswarmError

log = logging.getLogger(__name__)

PREFIX = "ps-"  # every namespace polyswarm makes starts with this
SUBNETS = "10.77"  # the radios' /24s (10.77.k.0): private; one per network on this machine
LAUNCH_HOST = 254  # the launch's own router on the radio (the observer's base station)
PORT = 7447  # each host's router, on its wifi0 address
IP_TIMEOUT_S = 10.0
OWNERS = Path("/run/polyswarm")  # which process made each run's network (a pid file a run)


class NetworkError(PolyswarmError):
    """A network namespace, link or bridge could not be made, changed or removed."""


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    try:
        res = subprocess.run(
            ["ip", *args], capture_output=True, text=True, timeout=IP_TIMEOUT_S, check=False
        )
    except (OSError, subprocess.TimeoutExpired) as e:
        raise NetworkError(f"ip {' '.join(args)}: {e}") from e
    if check and res.returncode != 0:
        raise NetworkError(f"ip {' '.join(args)}: {res.stderr.strip() or res.returncode}")
    return res


def check_can_build() -> None:
    """NetworkError (one line) unless this process may build namespaces."""
    if shutil.which("ip") is None:
        raise NetworkError("--netns needs the ip command (Debian package iproute2)")
    if os.geteuid() != 0:
        raise NetworkError("--netns needs root (it makes network namespaces, veths, a bridge)")


def _owner(run: str) -> Path:
    return OWNERS / f"netns-{run}.pid"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def sweep_stale() -> list[str]:
    """Remove the networks of runs whose process is gone (killed before it could clean
    up); a run without a pid file is someone else's and stays. Returns the namespaces
    removed."""
    removed = []
    for run in sorted({n[len(PREFIX) :].split("-", 1)[0] for n in namespaces()}):
        try:
            pid = int(_owner(run).read_text())
        except (OSError, ValueError):
            continue
        if _alive(pid):
            continue
        for n in namespaces():
            if n.startswith(f"{PREFIX}{run}-"):
                _ip("netns", "del", n, check=False)
                removed.append(n)
        _ip("link", "del", f"psbr-{run}"[:15], check=False)
        _owner(run).unlink(missing_ok=True)
    if removed:
        log.warning("network: removed %d namespaces left by a run that died", len(removed))
    return removed


def namespaces() -> list[str]:
    """The network namespaces polyswarm made that exist now."""
    out = _ip("netns", "list", check=False).stdout
    return [line.split()[0] for line in out.splitlines() if line.startswith(PREFIX)]


def _free_subnet() -> str:
    """A radio /24 no address of this machine's own namespace lies in (another network's
    bridge holds one)."""
    used = _ip("-o", "-4", "addr", "show").stdout
    for k in range(250):
        subnet = f"{SUBNETS}.{k}"
        if f" {subnet}." not in used:
            return subnet
    raise NetworkError(f"every radio subnet {SUBNETS}.0-249 is in use")


@dataclass
class FleetNetwork:
    run: str  # a short id: names are ps-<run>-<host>
    hosts: list[str]  # in the order their addresses are given (10.77.k.1, ...)
    sockets_dir: Path  # where the hosts' Unix sockets are
    subnet: str = f"{SUBNETS}.0"  # the radio's /24 (its first three numbers)
    made: bool = False

    @classmethod
    def create(cls, run: str, hosts: list[str], sockets_dir: Path) -> FleetNetwork:
        """Build the namespaces, the hosts' ``wifi0`` links and the bridge; on a failure
        halfway, what was made is removed again."""
        check_can_build()
        if len(hosts) > 250:
            raise NetworkError(f"{len(hosts)} hosts: the radio's /24 holds 250")
        sweep_stale()
        net = cls(run, list(hosts), Path(sockets_dir), _free_subnet())
        net.sockets_dir.mkdir(parents=True, exist_ok=True)
        try:
            OWNERS.mkdir(parents=True, exist_ok=True)
            _owner(run).write_text(str(os.getpid()))
            net._build()
        except NetworkError:
            net.remove()
            raise
        return net

    @property
    def bridge(self) -> str:
        return f"psbr-{self.run}"[:15]  # interface names hold 15 characters

    def namespace(self, host: str) -> str:
        return f"{PREFIX}{self.run}-{host}"

    def address(self, host: str) -> str:
        return f"{self.subnet}.{self.hosts.index(host) + 1}"

    def launch_endpoint(self) -> str:
        """The launch's router on the radio: a host's cut also cuts the observer off it."""
        return f"tcp/{self.subnet}.{LAUNCH_HOST}:{PORT}"

    def _peer(self, host: str) -> str:
        return f"ps{self.run}{self.hosts.index(host)}"[:15]  # the bridge's end of wifi0

    def _build(self) -> None:
        self.made = True
        _ip("link", "add", "name", self.bridge, "type", "bridge")
        _ip("addr", "add", f"{self.subnet}.{LAUNCH_HOST}/24", "dev", self.bridge)
        _ip("link", "set", self.bridge, "up")
        for host in self.hosts:
            ns, peer = self.namespace(host), self._peer(host)
            _ip("netns", "add", ns)
            _ip("link", "add", peer, "type", "veth", "peer", "name", "wifi0", "netns", ns)
            _ip("link", "set", peer, "master", self.bridge, "up")
            _ip("-n", ns, "link", "set", "lo", "up")
            _ip("-n", ns, "addr", "add", f"{self.address(host)}/24", "dev", "wifi0")
            _ip("-n", ns, "link", "set", "wifi0", "up")
        log.info(
            "network: %d hosts in namespaces %s*, bridge %s",
            len(self.hosts),
            self.namespace(""),
            self.bridge,
        )

    def wrap(self, host: str) -> list[str]:
        """The prefix that runs a command on ``host``."""
        return ["ip", "netns", "exec", self.namespace(host)]

    def tcp_endpoint(self, host: str) -> str:
        return f"tcp/{self.address(host)}:{PORT}"

    def unix_endpoint(self, host: str) -> str:
        return f"unixsock-stream/{self.sockets_dir.resolve() / f'{host}.sock'}"

    def listen(self, host: str) -> list[str]:
        """Where ``host``'s router listens: its radio, and its Unix socket."""
        return [self.tcp_endpoint(host), self.unix_endpoint(host)]

    def mesh(self, host: str) -> list[str]:
        """The routers ``host`` connects to: every host before it (one link per pair)."""
        return [self.tcp_endpoint(h) for h in self.hosts[: self.hosts.index(host)]]

    def cut(self, host: str) -> None:
        """``host`` out of range: its wifi0 down."""
        _ip("-n", self.namespace(host), "link", "set", "wifi0", "down")
        log.warning("network: %s cut off (wifi0 down)", host)

    def restore(self, host: str) -> None:
        _ip("-n", self.namespace(host), "link", "set", "wifi0", "up")
        log.warning("network: %s back in range (wifi0 up)", host)

    def remove(self) -> None:
        """Namespaces (and with them the veths) and the bridge removed; what is already
        gone is skipped. Sockets are left to the run folder."""
        if not self.made:
            return
        for host in self.hosts:
            _ip("netns", "del", self.namespace(host), check=False)
        _ip("link", "del", self.bridge, check=False)
        _owner(self.run).unlink(missing_ok=True)
        self.made = False
        left = [n for n in namespaces() if n.startswith(self.namespace(""))]
        if left:
            raise NetworkError(f"namespaces left behind: {', '.join(left)}")


@dataclass(frozen=True)
class Hosts:
    """Where each process of a launch runs and how it reaches Zenoh: with a network
    (``--netns``) each host's process is a router of the mesh, the coordinators' also
    linked to the launch's own router (the observer's) over the radio, so a cut host is
    cut off from it too; the simulator reaches each robot over its Unix socket; without
    a network, everyone is a client of the launch's router."""

    net: FleetNetwork | None
    endpoint: str  # the launch's router, for the observer, the view and the simulator

    @property
    def root(self) -> str:
        """Where the launch's router listens."""
        if self.net is None:
            return self.endpoint
        return f"{self.endpoint},{self.net.launch_endpoint()}"

    def wrap(self, host: str) -> list[str]:
        return [] if self.net is None else self.net.wrap(host)

    def coordinator_args(self, name: str = "coordinator") -> list[str]:
        if self.net is None:
            return ["--connect", self.endpoint]
        listen = ",".join(self.net.listen(name))
        mesh = [*self.net.mesh(name), self.net.launch_endpoint()]
        return ["--listen", listen, "--connect", ",".join(mesh)]

    def agent_args(self, rid: str) -> list[str]:
        if self.net is None:
            return []
        return [
            "--listen",
            ",".join(self.net.listen(rid)),
            "--connect",
            ",".join(self.net.mesh(rid)),
        ]

    def sim_args(self, ids: list[str]) -> list[str]:
        if self.net is None:
            return []
        return ["--robot-link", ",".join(f"{r}={self.net.unix_endpoint(r)}" for r in ids)]


@dataclass
class Outage:
    robot: str
    cut_s: float  # simulated seconds
    keyframes_at_cut: int  # the last its status told before the cut
    restore_s: float | None = None
    rejoined_s: float | None = None  # its first status heard after the restore
    keyframes_at_rejoin: int | None = None


@dataclass
class Outages:
    """The links a launch cut, and what the robots did meanwhile: the keyframes a robot
    made while out of range are the map it kept building on its own."""

    items: list[Outage] = field(default_factory=list)

    def cut(self, robot: str, t_s: float, keyframes: int) -> None:
        self.items.append(Outage(robot, t_s, keyframes))

    def restore(self, robot: str, t_s: float) -> None:
        for o in self.items:
            if o.robot == robot and o.restore_s is None:
                o.restore_s = t_s

    def status(self, robot: str, t_s: float, keyframes: int) -> None:
        for o in self.items:
            if o.robot == robot and o.restore_s is not None and o.rejoined_s is None:
                o.rejoined_s, o.keyframes_at_rejoin = t_s, keyframes

    def to_list(self) -> list[dict]:
        return [dataclasses.asdict(o) for o in self.items]


def maps_agree(state_dir: Path, ids: list[str]) -> dict[str, dict]:
    """After a run: each robot's own saved map against the coordinator's saved copy of
    it (same version and explored area: nothing it mapped is missing there)."""
    from agents.persist import load_agent, load_coordinator

    _, copies = load_coordinator(state_dir)
    out = {}
    for rid in ids:
        own = load_agent(state_dir, rid)
        copy = copies.get(rid)
        if own is None or copy is None:
            out[rid] = {"agree": False, "why": "no saved map" if own is None else "no copy"}
            continue
        a, b = own.map.explored_area(), copy.explored_area()
        out[rid] = {
            "agree": own.map.version == copy.version and abs(a - b) < 1e-6,
            "version": own.map.version,
            "copy_version": copy.version,
            "explored_m2": round(a, 3),
            "copy_explored_m2": round(b, 3),
        }
    return out
