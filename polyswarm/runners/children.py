"""The launch's child processes: started (in a host's network namespace when asked),
recorded, measured, restarted with backoff when they exit unexpectedly, and stopped
in order (the simulator and agents first, then the coordinators and the router)."""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

log = logging.getLogger(__name__)

STACK_DUMP_S = 0.2  # a child that did not stop gets this long to write its stack
SHUTDOWN_S = 4.0  # children get this long to exit after SIGTERM before SIGKILL
VIEW = "view"  # the live view: its exit does not end the mission
# stopped last, so that they receive what the robots sent last
HUB = ("coordinator", "router", *(f"coordinator{k}" for k in range(2, 10)))
HUB_SHUTDOWN_S = 1.5  # ... and given this much of SHUTDOWN_S (writing the coordinator's
#                       state is appending to its journal, not rewriting maps)
# a child that exits unexpectedly is restarted after RESTART_BASE_S, doubling with each
# restart up to RESTART_MAX_S (systemd's Restart=on-failure, RestartSec, on one machine);
# after MAX_RESTARTS of one child the mission stops (it is not a passing fault)
RESTART_BASE_S = 1.0
RESTART_MAX_S = 8.0
MAX_RESTARTS = 5
# every child is restarted: the simulator too, from the state it saves after every lidar
# tick (polyswarm.runners.simserve): its robots are where they were, its clock goes on
NOT_RESTARTED: tuple[str, ...] = ()


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Child:
    name: str
    proc: subprocess.Popen
    log_path: Path
    args: list[str] = field(default_factory=list)
    verbose: bool = False
    env: dict = field(default_factory=dict)
    nice: int = 0
    wrap: list[str] = field(default_factory=list)  # e.g. ip netns exec NS: the host it runs on


def _spawn(
    name: str,
    args: list[str],
    logs: Path,
    verbose: bool,
    extra_env: dict | None = None,
    nice: int = 0,
    wrap: list[str] | None = None,
) -> Child:
    log_path = logs / f"{name}.log"
    f = open(log_path, "a")  # noqa: SIM115 - kept open for the child's lifetime
    cmd = [*(wrap or []), sys.executable, "-m", "polyswarm"]
    cmd += (["-vv"] if verbose else ["-v"]) + args
    env = dict(os.environ, PYTHONUNBUFFERED="1", **(extra_env or {}))
    proc = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, env=env)
    f.close()
    if nice:
        try:  # after the start (a preexec_fn is unsafe with the launcher's Zenoh threads)
            os.setpriority(os.PRIO_PROCESS, proc.pid, os.getpriority(os.PRIO_PROCESS, 0) + nice)
        except OSError as e:
            log.warning("could not lower the priority of %s: %s", name, e)
    _record_pid(logs, name, proc.pid)
    return Child(name, proc, log_path, args, verbose, extra_env or {}, nice, wrap or [])


def _record_pid(logs: Path, name: str, pid: int) -> None:
    """``logs/pids.json``: each child's process id, for tools outside the launch."""
    path = logs / "pids.json"
    pids = json.loads(path.read_text()) if path.exists() else {}
    pids[name] = pid
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(pids, indent=1))
    tmp.replace(path)


def _rss_mb(child: Child | None) -> float | None:
    """Resident memory of a child process and its own children (the coordinator's replay
    processes), from Linux /proc, megabytes."""
    if child is None or child.proc.poll() is not None:
        return None
    total = None
    for pid in _process_tree(child.proc.pid):
        try:
            for line in Path(f"/proc/{pid}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total = (total or 0.0) + int(line.split()[1]) / 1024.0
        except OSError:  # it has just exited
            continue
    return total


def _process_tree(pid: int) -> list[int]:
    """``pid`` and its descendants (Linux /proc)."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        try:
            for task in Path(f"/proc/{p}/task").iterdir():
                todo += [int(c) for c in (task / "children").read_text().split()]
        except (OSError, ValueError):
            continue
    return out


def _stop_children(children: list[Child]) -> tuple[dict[str, int | None], set[str]]:
    """The simulator and agents first, then (once they are gone, so that the last deltas
    they sent reach the coordinator) the coordinator and router; SHUTDOWN_S in all. The
    exit codes, and the children still running when the stop began (one killed for not
    stopping in time was stopped by the launch, not crashed)."""
    running = {c.name for c in children if c.proc.poll() is None}
    deadline = time.monotonic() + SHUTDOWN_S
    hub = [c for c in children if c.name in HUB]
    for group, until in (
        ([c for c in children if c.name not in HUB], deadline - HUB_SHUTDOWN_S),
        (hub, deadline),
    ):
        for c in group:
            if c.proc.poll() is None:
                c.proc.send_signal(signal.SIGCONT)  # a frozen child could not stop
                c.proc.send_signal(signal.SIGTERM)
        for c in group:
            try:
                c.proc.wait(timeout=max(0.0, until - time.monotonic()))
            except subprocess.TimeoutExpired:
                log.warning("%s did not stop in time: killed (its stack is in its log)", c.name)
                with contextlib.suppress(OSError):
                    c.proc.send_signal(signal.SIGUSR1)  # faulthandler: where it was stuck
                    time.sleep(STACK_DUMP_S)
                c.proc.kill()
                c.proc.wait()
    return {c.name: c.proc.returncode for c in children}, running


@dataclass
class Supervision:
    """Children restarted by the launch: counts, and restarts waiting for their time."""

    restarts: dict[str, int] = field(default_factory=dict)
    pending: dict[str, float] = field(default_factory=dict)  # name -> monotonic restart time


def make_supervise(sup: Supervision):
    def supervise(children, faulted, restart: bool, logs: Path, now: float) -> str | None:
        """Restart children that exited unexpectedly (not those fault injection killed);
        a reason to stop the mission, or None."""
        for k, c in enumerate(children):
            if c.proc.poll() is None or c.name in faulted:
                continue
            if c.name in sup.pending:
                if now >= sup.pending[c.name]:
                    del sup.pending[c.name]
                    children[k] = _spawn(c.name, c.args, logs, c.verbose, c.env, c.nice, c.wrap)
                    log.warning("%s restarted (restart %d)", c.name, sup.restarts[c.name])
                continue
            code = c.proc.returncode
            if c.name == VIEW and not restart:
                continue
            if not restart or c.name in NOT_RESTARTED:
                return f"process exited: {c.name} (code {code})"
            n = sup.restarts.get(c.name, 0) + 1
            if n > MAX_RESTARTS:
                return f"process keeps exiting: {c.name} ({MAX_RESTARTS} restarts)"
            sup.restarts[c.name] = n
            delay = min(RESTART_MAX_S, RESTART_BASE_S * 2 ** (n - 1))
            sup.pending[c.name] = now + delay
            log.warning("%s exited (code %s): restarting in %.0f s", c.name, code, delay)
        return None

    return supervise
