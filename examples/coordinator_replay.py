"""The coordinator's cycle on recorded inputs: old code against new in seconds.

    python examples/coordinator_replay.py record trace.pkl [ROBOTS] [SIM_SECONDS]  # 10, 60
    python examples/coordinator_replay.py replay trace.pkl [REPEATS]
    python examples/coordinator_replay.py profile trace.pkl [TOP]  # 10

``record`` runs the 10-robot maze exploration in one process (what ``polyswarm bench
explore --load-robots 10`` measures, about 160 s) and saves every call the coordinator
got, in order: robots alive, poses, statuses, map deltas and merges, flushes and
cycles. ``replay`` feeds them to a fresh ``Coordinator`` and prints the cycle time p50 /
p95 / max (ms, merges since the previous cycle included, the first cycle left out, as
the benchmark does) and the processor time of all cycles (s, steadier than the
percentiles on a shared machine), the median over REPEATS replays, a digest of the
targets and assignments (same digest: same decisions) and one of the merged map's cells
at the end (same digest: the same map, bit for bit). The robots' recorded merges are
replayed too, each checked against the digest its robot sent: a merge that now comes
out differently is counted as refused (0 when the merge code is unchanged in effect).
The robots do not react to the replayed coordinator: its inputs are the recorded ones
whatever it decides.

``profile`` replays once under cProfile, profiling the coordinator's flushes and cycles
only (not the robots' merges), and prints where their time goes: the share of GEOS
calls (which release the GIL, so only they could overlap on worker threads), numpy,
polyswarm's own Python and the rest; the TOP functions by own time; and the TOP
slowest cycles with the robot cells that arrived before each (are the slow cycles a
start-up burst or spread over the run?).

``POLYSWARM_CODE=/other/checkout`` imports the code from another checkout (``git
worktree add /tmp/old COMMIT``); run both one after the other on the same trace.
"""

from __future__ import annotations

import os
import sys

if os.environ.get("POLYSWARM_CODE"):
    sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in repr(f)]
    sys.path.insert(0, os.environ["POLYSWARM_CODE"])

import cProfile
import hashlib
import pickle
import pstats
import time

import numpy as np

import agents.coordinator as coordinator_module
from polyswarm.config import Config
from polyswarm.errors import MapError
from polyswarm.polymap import cells_digest

CALLS = ("on_alive", "on_pose", "on_status", "on_robot_delta", "on_robot_merge", "on_robot_map")


def record(out: str, robots: int = 10, sim_s: float = 60.0) -> None:
    from polyswarm.benchmarks.inproc import explore_in_process

    Coordinator = coordinator_module.Coordinator
    trace: list = []
    for name in (*CALLS, "flush", "cycle"):
        inner = getattr(Coordinator, name)

        def wrapper(self, *args, _inner=inner, _name=name):
            trace.append((_name, args))
            return _inner(self, *args)

        setattr(Coordinator, name, wrapper)
    t0 = time.monotonic()
    run = explore_in_process("data:maze", robots, sim_s, seed=0)
    starts = {rid: info.start for rid, info in run.coordinator.robots.items()}
    with open(out, "wb") as f:
        pickle.dump({"robots": starts, "trace": trace}, f)
    cycles = sum(1 for n, _ in trace if n == "cycle")
    print(f"{len(trace)} calls, {cycles} cycles, {time.monotonic() - t0:.0f} s")


def replay_once(data: dict) -> tuple[np.ndarray, np.ndarray, str, int]:
    coord = coordinator_module.Coordinator(Config(), data["robots"])
    digest = hashlib.sha256()
    ids: dict[int, int] = {}  # target ids start from the clock: numbered in order here
    refused = 0
    for name, args in data["trace"]:
        try:
            out = getattr(coord, name)(*args)
        except MapError:  # a robot's merge that replays differently, or a gap after it
            refused += 1
            continue
        if name == "cycle":
            for tid, t in sorted(coord.targets.items()):
                k = ids.setdefault(tid, len(ids))
                digest.update(f"{k}:{t.goal.round(6).tolist()}:{t.utility_m:.6f};".encode())
            for rid, a in sorted(out.assignments.items()):
                digest.update(f"{rid}>{ids.get(a.target, a.target)};".encode())
    digest.update(f"map {cells_digest(coord.merged.cells.values()):08x}".encode())
    ms, cpu = np.array(coord.cycle_ms[1:]), np.array(coord.cycle_cpu_ms[1:])
    return ms, cpu, digest.hexdigest()[:12], refused


def replay(path: str, repeats: int = 3) -> None:
    with open(path, "rb") as f:
        data = pickle.load(f)
    rows = []
    for k in range(repeats):
        ms, cpu, digest, refused = replay_once(data)
        rows.append([np.percentile(ms, 50), np.percentile(ms, 95), ms.max(), cpu.sum() / 1e3])
        print(
            f"replay {k + 1}: {ms.size} cycles, p50 {rows[-1][0]:.1f} ms, p95 {rows[-1][1]:.1f} "
            f"ms, max {rows[-1][2]:.1f} ms, processor time {rows[-1][3]:.2f} s, digest {digest}, "
            f"robot updates refused {refused}"
        )
    p50, p95, mx, cpu_s = np.median(rows, axis=0)
    print(
        f"median of {repeats}: p50 {p50:.1f} ms, p95 {p95:.1f} ms, max {mx:.1f} ms, "
        f"processor time {cpu_s:.2f} s"
    )


# shapely's modules whose functions are one vectorised GEOS call each
_GEOS_MODULES = ("set_operations.py", "predicates.py", "constructive.py", "creation.py")


def _library(path: str, name: str) -> str:
    """Which library a profiled function belongs to."""
    if (
        ("shapely" in path and path.endswith(_GEOS_MODULES))
        or "STRtree" in name
        or "shapely.lib" in name
    ):
        return "GEOS (shapely)"
    if "shapely" in path or "shapely" in name:
        return "shapely"
    if "numpy" in path or "numpy" in name or "ndarray" in name or "ufunc" in name:
        return "numpy"
    if "polyswarm" in path or "agents" in path:
        return "polyswarm Python"
    return "other (builtins, stdlib, scipy)"


def profile(path: str, top: int = 10) -> None:
    with open(path, "rb") as f:
        data = pickle.load(f)
    coord = coordinator_module.Coordinator(Config(), data["robots"])
    prof = cProfile.Profile()
    cycles, arrived = [], 0
    for name, args in data["trace"]:
        on = name in ("flush", "cycle")  # a cycle flushes first
        if on:
            arrived += sum(len(cells) for cells in coord._pending.values())
            prof.enable()
        try:
            getattr(coord, name)(*args)
        except MapError:
            pass
        finally:
            if on:
                prof.disable()
        if name == "cycle":
            cycles.append((coord.cycle_ms[-1], coord.now, arrived, len(coord.merged.cells)))
            arrived = 0
    stats = pstats.Stats(prof)
    share: dict[str, float] = {}
    for (fn, _, name), (_, _, own_s, _, _) in stats.stats.items():
        share[_library(fn, name)] = share.get(_library(fn, name), 0.0) + own_s
    total = sum(share.values())
    print(f"flushes and cycles under cProfile: {total:.2f} s (profiling adds to Python calls)")
    for lib, s in sorted(share.items(), key=lambda kv: -kv[1]):
        print(f"  {lib:32s} {s:6.2f} s  {100 * s / total:5.1f} %")
    print(f"top {top} functions by own time:")
    rows = sorted(stats.stats.items(), key=lambda kv: -kv[1][2])[:top]
    for (fn, line, name), (_, calls, own_s, _, _) in rows:
        print(f"  {own_s:6.2f} s {calls:7d} calls  {os.path.basename(fn)}:{line} {name}")
    print(
        f"the {top} slowest cycles (under the profiler; the first left out, as the benchmark does):"
    )
    for ms, t, n_in, n_cells in sorted(cycles[1:], reverse=True)[:top]:
        print(
            f"  {ms:6.1f} ms at {t:5.1f} s simulated: {n_in} robot cells in, "
            f"merged map {n_cells} cells"
        )


if __name__ == "__main__":
    verb, *rest = sys.argv[1:]
    if verb == "record":
        record(rest[0], *(int(rest[1]),) if len(rest) > 1 else (), *map(float, rest[2:3]))
    elif verb == "profile":
        profile(rest[0], *(int(r) for r in rest[1:2]))
    else:
        replay(rest[0], *(int(r) for r in rest[1:2]))
