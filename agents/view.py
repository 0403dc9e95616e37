"""``polyswarm view``: the mission live in a browser, from the simulator or a real fleet.

A separate process that only listens: it subscribes to the swarm's keys on Zenoh (the
merged map's deltas, robots' poses and statuses, assignments, the coordinator's status,
agents' liveliness), fetches the merged map from its queryable when it starts or misses
a delta, and serves one page on HTTP with a websocket (aiohttp). The page draws the
merged PolyMap as SVG, cell by cell: a delta re-sends only the cells it changed.

Websocket messages (JSON), server to page:

* ``{"t": "cells", "ver": n, "full": bool, "cells": {"i,j": cell}}``: a cell is
  ``{"explored": [svg path, ...], "obstacles": svg path, "frontiers": svg path}``, one
  explored path per polygon of the cell (``full``: every cell, the page drops the rest);
* ``{"t": "state", ...}``: mission, simulated time, explored-area curve, the frontier
  targets and the blacklisted ones, and per robot pose, recent trail, state, liveness,
  target, frontier, path and bytes sent;

and page to server ``{"t": "shown", "ver": n, "at_ms": wall ms}`` once a map version is
drawn, from which the view measures its display latency (``ViewStats``).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from importlib import resources

import numpy as np

from polyswarm.errors import DecodeError, MapError
from polyswarm.polymap import Cell, GridPolyMap, VectorType
from protocols.chunks import MapChunk
from protocols.keys import SwarmKeys
from protocols.mapcodec import decode_delta, decode_map
from protocols.messages import Assignment, Clock, CoordinatorStatus, Pose, RobotStatus

log = logging.getLogger(__name__)

TRAIL_POINTS = 300  # recent poses drawn behind a robot (2 Hz poses: 2.5 minutes)
TRAIL_STEP_M = 0.05  # a pose closer than this to the trail's last point is not added
CURVE_POINTS = 2000  # explored-area samples kept for the curve
STATE_PERIOD_S = 0.25  # robot state to the page (4 Hz)
MAP_PERIOD_S = 0.1  # changed cells to the page at most this often
RESYNC_AFTER_S = 1.0  # the coordinator's map version ahead of ours this long: fetch it
SHUTDOWN_S = 1.0  # pages still connected get this long to close when the view stops
PAGE_FILES = {"/": "index.html", "/view.js": "view.js", "/view.css": "view.css"}


def _fmt(v: float) -> str:
    return f"{v:.3f}".rstrip("0").rstrip(".")


def ring_path(xy: np.ndarray) -> str:
    return "M" + "L".join(f"{_fmt(x)} {_fmt(y)}" for x, y in xy) + "Z"


def segments_path(starts: np.ndarray, ends: np.ndarray) -> str:
    return "".join(
        f"M{_fmt(a[0])} {_fmt(a[1])}L{_fmt(b[0])} {_fmt(b[1])}"
        for a, b in zip(starts, ends, strict=True)
    )


def cell_svg(cell: Cell) -> dict:
    """One cell as SVG path data (metres, y up: the page flips it)."""
    explored = ["".join(ring_path(r.xy) for r in p.rings()) for p in cell.polygons]
    out = {"explored": explored}
    for name, kind in (("obstacles", VectorType.OBSTACLE), ("frontiers", VectorType.FRONTIER)):
        s, e = cell.vectors_of_type(kind)
        out[name] = segments_path(s, e)
    return out


@dataclass
class RobotView:
    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0
    seen: bool = False
    trail: deque = field(default_factory=lambda: deque(maxlen=TRAIL_POINTS))
    state: str = "starting"
    alive: bool = True
    target: int = -1
    goal: tuple[float, float] | None = None
    frontier: tuple = ()
    path: tuple = ()
    bytes_sent: int = 0


@dataclass
class ViewStats:
    deltas: int = 0
    fetches: int = 0
    bad_messages: int = 0
    received_at: dict = field(default_factory=dict)  # map version -> published (wall s)
    display_latency_ms: list = field(default_factory=list)


class ViewState:
    """What the page shows, fed from Zenoh's side and read from the web server's."""

    def __init__(self, keys: SwarmKeys, robot_radius_m: float) -> None:
        self.keys = keys
        self.radius = robot_radius_m
        self.lock = threading.Lock()
        self.map = GridPolyMap()
        self.robots: dict[str, RobotView] = {}
        self.mission = "starting"
        self.coordinator_version = -1
        self.sim_t: float | None = None
        self.curve: deque = deque(maxlen=CURVE_POINTS)  # (time s, explored m2)
        self.targets: tuple = ()  # the coordinator's frontier targets (goal points)
        self.blacklisted: tuple = ()  # targets it gave up on
        self.changed: set = set()  # cells changed since the page was last sent them
        self.full = True  # the page needs every cell
        self.need_map = True
        self._behind_since: float | None = None
        self.stats = ViewStats()
        self.t0 = time.monotonic()
        self.cpu0 = time.process_time()  # start-up (imports) not counted

    def robot(self, rid: str) -> RobotView:
        return self.robots.setdefault(rid, RobotView())

    def now(self) -> float:
        return self.sim_t if self.sim_t is not None else time.monotonic() - self.t0

    # -- from Zenoh ---------------------------------------------------------------------

    def handle(self, item) -> None:
        from agents.session import is_alive_change

        with self.lock:
            alive = is_alive_change(item)
            if alive is not None:
                name = self.keys.alive_name(item.key)
                if name is not None and name[0] == "agent":
                    self.robot(name[1]).alive = alive
                return
            self._message(item)

    def _message(self, item) -> None:
        msg, rid = item.msg, self.keys.robot_of(item.key)
        if isinstance(msg, Pose) and rid:
            r = self.robot(rid)
            r.x, r.y, r.theta, r.seen = msg.x, msg.y, msg.theta, True
            if (
                not r.trail
                or np.hypot(r.trail[-1][0] - msg.x, r.trail[-1][1] - msg.y) > TRAIL_STEP_M
            ):
                r.trail.append((round(msg.x, 2), round(msg.y, 2)))
        elif isinstance(msg, RobotStatus) and rid:
            r = self.robot(rid)
            r.state, r.target, r.bytes_sent, r.path = (
                str(msg.state),
                msg.target,
                msg.bytes_sent,
                msg.path,
            )
        elif isinstance(msg, Assignment):
            r = self.robot(item.key.rsplit("/", 1)[-1])
            r.goal = None if msg.target < 0 else msg.goal
            r.frontier = msg.frontier
        elif isinstance(msg, Clock):
            self.sim_t = msg.t_s
        elif isinstance(msg, CoordinatorStatus):
            self.mission = str(msg.state)
            self.coordinator_version = msg.map_version
            self.targets, self.blacklisted = msg.targets, msg.blacklisted
            for name in msg.robots:
                self.robot(name)
            if not self.curve or self.now() - self.curve[-1][0] >= 1.0:
                self.curve.append((round(self.now(), 1), round(msg.explored_m2, 1)))
            self._check_behind()
        elif isinstance(msg, MapChunk) and item.payload is not None and rid is None:
            self._delta(item.payload, item.routed_at)

    def _delta(self, payload: bytes, sent_at: float | None = None) -> None:
        try:
            delta = decode_delta(payload)
            self.map = self.map.apply_delta(delta)
        except (DecodeError, MapError) as e:
            log.debug("view: merged delta not applied (%s): fetching the map", e)
            self.need_map = True
            return
        self.stats.deltas += 1
        # from its publication (the router's stamp) where there is one, else its arrival
        self.stats.received_at[self.map.version] = sent_at or time.time()
        self.changed.update(c.index for c in delta.cells)

    def _check_behind(self) -> None:
        if self.coordinator_version > self.map.version:
            self._behind_since = self._behind_since or time.monotonic()
            if time.monotonic() - self._behind_since > RESYNC_AFTER_S:
                self.need_map, self._behind_since = True, None
        else:
            self._behind_since = None

    def set_map(self, pmap: GridPolyMap) -> None:
        with self.lock:
            self.map = pmap
            self.full, self.changed, self.need_map = True, set(), False
            self.stats.fetches += 1
            self.stats.received_at[pmap.version] = time.time()

    # -- to the page ----------------------------------------------------------------------

    def take_cells(self) -> dict | None:
        """The cells the page lacks, or None when it has them all."""
        with self.lock:
            if not self.full and not self.changed:
                return None
            cells = self.map.cells
            idx = list(cells) if self.full else sorted(self.changed)
            out = {
                "t": "cells",
                "ver": self.map.version,
                "full": self.full,
                "cells": {
                    f"{i},{j}": cell_svg(cells[(i, j)]) if (i, j) in cells else None for i, j in idx
                },
                "polygons": self.map.polygon_count(),
            }
            self.full, self.changed = False, set()
            return out

    def state(self) -> dict:
        with self.lock:
            robots = {}
            for rid, r in sorted(self.robots.items()):
                robots[rid] = {
                    "x": r.x,
                    "y": r.y,
                    "th": r.theta,
                    "seen": r.seen,
                    "trail": list(r.trail),
                    "state": r.state if r.alive else "lost",
                    "alive": r.alive,
                    "target": r.target,
                    "goal": r.goal,
                    "frontier": [list(p) for p in r.frontier],
                    "path": [list(p) for p in r.path],
                    "bytes": r.bytes_sent,
                }
            return {
                "t": "state",
                "mission": self.mission,
                "time_s": round(self.now(), 1),
                "simulated": self.sim_t is not None,
                "ver": self.map.version,
                "radius": self.radius,
                "curve": list(self.curve),
                "targets": [list(p) for p in self.targets],
                "blacklisted": [list(p) for p in self.blacklisted],
                "robots": robots,
            }

    def figures(self) -> dict:
        """What the view measured of itself (``polyswarm bench view``)."""
        lat = self.stats.display_latency_ms
        wall = time.monotonic() - self.t0
        cpu = time.process_time() - self.cpu0
        return {
            "deltas": self.stats.deltas,
            "fetches": self.stats.fetches,
            "bad_messages": self.stats.bad_messages,
            "displayed_versions": len(lat),
            "display_latency_p50_ms": float(np.median(lat)) if lat else None,
            "display_latency_p95_ms": float(np.percentile(lat, 95)) if lat else None,
            "cpu_s": cpu,
            "wall_s": wall,
            "cpu_share": cpu / wall if wall > 0 else 0.0,
        }

    def shown(self, ver: int, at_ms: float) -> None:
        with self.lock:
            t = self.stats.received_at.pop(ver, None)
            for old in [v for v in self.stats.received_at if v < ver]:
                self.stats.received_at.pop(old)
            if t is not None:
                self.stats.display_latency_ms.append(at_ms - t * 1e3)


def listen(bus, state: ViewState, stop: threading.Event) -> None:
    """Zenoh side: subscribe, then apply what arrives until ``stop``."""
    keys = state.keys
    bus.subscribe(keys.merged_delta, MapChunk)
    bus.subscribe(keys.all_robots("pose"), Pose)
    bus.subscribe(keys.all_robots("status"), RobotStatus)
    bus.subscribe(f"{keys.prefix}/coordinator/assignment/*", Assignment)
    bus.subscribe(keys.coordinator_status, CoordinatorStatus)
    bus.subscribe(keys.clock, Clock)
    bus.watch_alive(keys.all_alive("agent"))
    while not stop.is_set():
        for item in bus.poll(timeout_s=0.05):
            try:
                state.handle(item)
            except DecodeError as e:
                state.stats.bad_messages += 1
                log.warning("view: bad message on %s: %s", item.key, e)
        if state.need_map:
            got = bus.fetch_map(keys.merged_map, timeout_s=2.0)
            if got is not None:
                try:
                    state.set_map(decode_map(got[0]))
                except DecodeError as e:
                    log.warning("view: bad merged map: %s", e)


# --- the web server ---------------------------------------------------------------------


def make_app(state: ViewState):
    from aiohttp import WSMsgType, web

    page = resources.files("agents") / "view_page"
    sockets: set = set()

    async def static(request):
        name = PAGE_FILES[request.path]
        kind = {"html": "text/html", "js": "text/javascript", "css": "text/css"}
        return web.Response(
            text=(page / name).read_text(), content_type=kind[name.rsplit(".", 1)[1]]
        )

    async def ws_handler(request):
        ws = web.WebSocketResponse(heartbeat=10.0)
        await ws.prepare(request)
        with state.lock:
            state.full = True  # a new page needs every cell
        sockets.add(ws)
        try:
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    try:
                        data = json.loads(msg.data)
                        if data.get("t") == "shown":
                            state.shown(int(data["ver"]), float(data["at_ms"]))
                    except (ValueError, KeyError, TypeError):
                        log.debug("view: bad message from a page")
        finally:
            sockets.discard(ws)
        return ws

    async def push(app):
        last_state = 0.0
        while True:
            await asyncio.sleep(MAP_PERIOD_S)
            out = []
            if sockets:
                cells = state.take_cells()
                if cells is not None:
                    out.append(json.dumps(cells))
                if time.monotonic() - last_state >= STATE_PERIOD_S:
                    last_state = time.monotonic()
                    out.append(json.dumps(state.state()))
            for ws in list(sockets):
                for text in out:
                    try:
                        await ws.send_str(text)
                    except (ConnectionError, RuntimeError):
                        sockets.discard(ws)

    async def start(app):
        app["push"] = asyncio.create_task(push(app))

    async def cleanup(app):
        app["push"].cancel()
        for ws in list(sockets):
            with contextlib.suppress(asyncio.TimeoutError, ConnectionError):
                await asyncio.wait_for(ws.close(), SHUTDOWN_S)

    app = web.Application()
    for path in PAGE_FILES:
        app.router.add_get(path, static)
    app.router.add_get("/ws", ws_handler)
    app.on_startup.append(start)
    app.on_cleanup.append(cleanup)
    return app


def serve(session_spec, swarm: str, host: str, port: int, robot_radius_m: float, stop) -> ViewState:
    """Run the view until ``stop``: Zenoh on a thread, the web server on this one."""
    from aiohttp import web

    from agents.session import Bus, open_session

    state = ViewState(SwarmKeys(swarm), robot_radius_m)
    with open_session(session_spec) as session:
        bus = Bus(session, "view")
        zenoh_side = threading.Thread(target=listen, args=(bus, state, stop), daemon=True)
        zenoh_side.start()

        async def main() -> None:
            runner = web.AppRunner(make_app(state))
            await runner.setup()
            await web.TCPSite(runner, host, port, shutdown_timeout=SHUTDOWN_S).start()
            log.info("view on http://%s:%d/", host, port)
            while not stop.is_set():
                await asyncio.sleep(0.2)
            await runner.cleanup()

        try:
            asyncio.run(main())
        finally:
            stop.set()
            zenoh_side.join(timeout=5)
            bus.close()
    return state
