"""``polyswarm agent``, ``polyswarm coordinator`` and ``polyswarm launch``."""

from __future__ import annotations

import math
from pathlib import Path

import typer

from polyswarm.cli import PROFILE_HELP, app, exit_now, load_cfg
from polyswarm.errors import ConfigError, SimulationError

CONFIG_OPT = typer.Option(None, "--config", "-c", help="TOML config file.")
CONNECT_HELP = "Zenoh router to connect to, e.g. tcp/10.0.0.5:7447 (default: comms.endpoint)."
ZENOH_HELP = "Zenoh JSON5 config file (LAN, TLS, ACL); --connect or --listen still applies."


def _pose(text: str | None):
    if text is None:
        return None
    try:
        x, y, th = (float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(
            f"--start must be x,y,theta in metres and radians, got {text!r}"
        ) from None
    return (x, y, th)


def session_spec(listen, connect, zconf: str, default: str, router: bool):
    """The Zenoh session of ``--listen`` and ``--connect`` (comma-separated endpoints):
    both, a router of a mesh (listening, and connecting to the other routers); listen
    alone, a router; connect alone, a client; neither, ``default`` as a router
    (``router``) or as the router to connect to."""
    from agents.session import Mode, SessionSpec

    def split(text):
        return tuple(e.strip() for e in (text or "").split(",") if e.strip())

    if listen:
        return SessionSpec(Mode.ROUTER, split(listen), split(connect), zconf)
    if connect:
        return SessionSpec(Mode.CLIENT, (), split(connect), zconf)
    return SessionSpec.router(default, zconf) if router else SessionSpec.client(default, zconf)


def _replay(replay: Path, cfg, robot_id: str, rate: float, scan_topic, odom_topic):
    """``agent --replay``: the configuration for the recording (a bag's mount and
    no-return value), the function that attaches its player to the agent's session, and
    the recording's start pose (x,y,theta)."""
    import dataclasses
    import threading

    from polyswarm.runners.replay import BagPlayer, LogPlayer, start_player
    from protocols.bags import is_bag
    from protocols.keys import SwarmKeys
    from protocols.tf import choose_mount

    if is_bag(replay):
        # the bag's messages arrive as ROS 2 CDR, as from a robot through the bridge
        io = dataclasses.replace(cfg.agent, source="ros2", output="native")
        player = BagPlayer(replay, io, rate, scan_topic, odom_topic)
        mount, _ = choose_mount(cfg.slam.mount, player.bag.mounts, str(replay))
        lidar = dataclasses.replace(cfg.sim.lidar, out_of_range=player.bag.no_return)
        cfg = dataclasses.replace(
            cfg,
            agent=io,
            slam=dataclasses.replace(cfg.slam, mount=mount),
            sim=dataclasses.replace(cfg.sim, lidar=lidar),
        )
    else:
        player = LogPlayer(replay, rate)
        # the log's scans arrive as native messages; commands carry the acknowledgements
        cfg = dataclasses.replace(
            cfg, agent=dataclasses.replace(cfg.agent, source="native", output="native")
        )
    me = SwarmKeys(cfg.comms.swarm).robot(robot_id)

    def attach(session, agent, stop_event):
        _thread, bus, sub = start_player(player, session, me, stop_event)

        def finish() -> None:  # all scans published and processed: stop the agent
            player.done.wait()
            deadline = threading.Event()
            for _ in range(600):
                if agent.stats.scans >= player.published or stop_event.is_set():
                    break
                deadline.wait(0.1)
            stop_event.set()

        threading.Thread(target=finish, daemon=True).start()

        def detach() -> None:
            sub.undeclare()
            bus.close()

        return detach

    return cfg, attach, ",".join(str(v) for v in player.start_pose)


def _agent_start(start: str | None, cfg, robot_id: str):
    """The agent's start pose and whether it is in the shared frame: --start, else
    [[robots]], else (0, 0, 0) in a frame of its own (the coordinator finds it)."""
    import logging

    from polyswarm.config import known_starts

    pose = _pose(start)
    frame_known = True
    if pose is None:
        starts = known_starts(cfg.robots)
        if robot_id not in starts:
            logging.getLogger("polyswarm").warning(
                "no start pose for %s (no --start, not in [[robots]]): using (0, 0, 0)", robot_id
            )
            pose = (0.0, 0.0, 0.0)
        elif starts[robot_id] is None:
            logging.getLogger("polyswarm").info(
                "%s: start pose not given: mapping in its own frame until the coordinator "
                "finds it in the shared map",
                robot_id,
            )
            pose, frame_known = (0.0, 0.0, 0.0), False
        else:
            pose = tuple(starts[robot_id])
    return pose, frame_known


@app.command("agent")
def agent_cmd(
    robot_id: str = typer.Option(..., "--id", help="Robot id (a key chunk, e.g. r1)."),
    config: Path | None = CONFIG_OPT,
    connect: str | None = typer.Option(None, help=CONNECT_HELP),
    zenoh_config: Path | None = typer.Option(None, help=ZENOH_HELP),
    start: str | None = typer.Option(
        None, help="Start pose x,y,theta (metres, radians) in the shared map frame."
    ),
    duration: float = typer.Option(
        0.0, "--wall-limit", help="Stop after this many wall-clock seconds (0: run on)."
    ),
    replay: Path | None = typer.Option(
        None,
        help="Feed this CARMEN log (.log or .log.gz) or ROS bag (ROS 1 .bag; rosbag2 "
        "folder, .mcap or .db3) instead of live sensors.",
    ),
    scan_topic: str | None = typer.Option(
        None, help="--replay of a bag: its sensor_msgs/LaserScan topic (default: the only one)."
    ),
    odom_topic: str | None = typer.Option(
        None, help="--replay of a bag: its nav_msgs/Odometry topic (default: the only one)."
    ),
    rate: float = typer.Option(
        1.0, help="Replay speed: log seconds per wall second (0: as fast as the agent runs)."
    ),
    listen: str | None = typer.Option(
        None,
        help="Be the Zenoh router yourself, listening on these endpoints (comma separated, "
        "e.g. tcp/127.0.0.1:7447): try an agent alone; with --connect, a router of a mesh.",
    ),
    out: Path | None = typer.Option(
        None, help="Write the agent's final map here (.polymap; .svg/.png next to it)."
    ),
) -> None:
    """Run a robot agent: PolySLAM, map deltas, planning and local control over Zenoh."""

    from agents.agent_node import run_agent
    from agents.session import stop_on_signals
    from polyswarm.config import load_config
    from protocols.keys import check_name

    check_name(robot_id, "robot id")
    cfg = load_config(config)
    attach = None
    stop = stop_on_signals()
    if replay is not None:
        cfg, attach, replay_start = _replay(replay, cfg, robot_id, rate, scan_topic, odom_topic)
        start = start or replay_start
    pose, frame_known = _agent_start(start, cfg, robot_id)
    zconf = str(zenoh_config or cfg.comms.zenoh_config or "")
    spec = session_spec(listen, connect, zconf, cfg.comms.endpoint, router=False)
    agent = run_agent(
        robot_id,
        cfg,
        pose,
        spec,
        stop=stop,
        duration_s=duration,
        attach=attach,
        frame_known=frame_known,
    )
    if out is not None:
        from polyswarm.io.export import export_map
        from protocols.files import write_polymap

        out.parent.mkdir(parents=True, exist_ok=True)
        write_polymap(agent.slam.map, out, cfg.map.whole_map_precision_m)
        export_map(agent.slam.map, out.with_suffix(".svg"))
        export_map(agent.slam.map, out.with_suffix(".png"))
    s = agent.stats
    typer.echo(
        f"{robot_id}: {s.scans} scans, {s.keyframes} keyframes, {s.distance_m:.1f} m, "
        f"{agent.bytes_sent} bytes sent, {s.refused} messages refused",
        err=True,
    )
    exit_now()  # state saved, session closed: no slow teardown


@app.command("view")
def view_cmd(
    connect: str | None = typer.Option(None, help=CONNECT_HELP),
    config: Path | None = CONFIG_OPT,
    swarm: str | None = typer.Option(None, help="Swarm name (default: comms.swarm)."),
    zenoh_config: Path | None = typer.Option(None, help=ZENOH_HELP),
    host: str = typer.Option("127.0.0.1", help="Address the web page is served on."),
    port: int = typer.Option(8000, min=0, max=65535, help="Port of the web page."),
    stats: Path | None = typer.Option(
        None, help="Write the view's figures here at exit (JSON: display latency, CPU)."
    ),
) -> None:
    """The mission live in a browser: merged map, robots, targets, paths (only listens)."""
    import json

    from agents.session import SessionSpec, stop_on_signals
    from agents.view import serve
    from polyswarm.config import load_config

    cfg = load_config(config)
    zconf = str(zenoh_config or cfg.comms.zenoh_config or "")
    spec = SessionSpec.client(connect or cfg.comms.endpoint, zconf)
    typer.echo(f"polyswarm view: http://{host}:{port}/", err=True)
    state = serve(
        spec, swarm or cfg.comms.swarm, host, port, cfg.nav.robot_radius_m, stop_on_signals()
    )
    figures = state.figures()
    if stats is not None:
        stats.write_text(json.dumps(figures, indent=2))
    p95 = figures["display_latency_p95_ms"]
    shown = f", display latency p95 {p95:.0f} ms" if p95 is not None else ""
    typer.echo(
        f"view: {figures['deltas']} merged deltas, {figures['fetches']} map fetches{shown}, "
        f"{100 * figures['cpu_share']:.1f} % of a core",
        err=True,
    )


@app.command("coordinator")
def coordinator_cmd(
    config: Path | None = CONFIG_OPT,
    listen: str | None = typer.Option(
        None,
        help="Endpoints the built-in Zenoh router listens on, comma separated (default: "
        "comms.endpoint); with --connect too, a router of a mesh.",
    ),
    zenoh_config: Path | None = typer.Option(None, help=ZENOH_HELP),
    strategy: str | None = typer.Option(None, help="hungarian, greedy or nearest."),
    connect: str | None = typer.Option(
        None,
        help="Connect to these Zenoh routers (comma separated): alone, as a client instead "
        "of being the router.",
    ),
    name: str = typer.Option(
        "coordinator", help="This coordinator's name (a key chunk); others keep state apart."
    ),
    standby: bool = typer.Option(
        False,
        "--standby",
        help="Start silent and take over when no active coordinator has been heard for 6 s.",
    ),
) -> None:
    """Run the coordinator (and the Zenoh router): merged map, frontiers, assignment."""
    from agents.coordinator_process import run_coordinator
    from polyswarm.config import load_config, with_overrides

    cfg = load_config(config)
    if strategy is not None:
        cfg = with_overrides(cfg, {"explore": {"strategy": strategy}})
    zconf = str(zenoh_config or cfg.comms.zenoh_config or "")
    spec = session_spec(listen, connect, zconf, cfg.comms.endpoint, router=True)
    coord = run_coordinator(cfg, spec, name=name, standby=standby)
    typer.echo(
        f"coordinator: mission {coord.state}, merged map {coord.merged.explored_area():.1f} m2, "
        f"{coord.bytes_sent} bytes sent",
        err=True,
    )
    exit_now()  # state saved, session closed: no slow teardown


def _check_launch_args(strategy: str, link_faults: str, wrong_anchor: str, start_error: str):
    """Refuse a bad --strategy, --link-faults, --wrong-anchor or --start-error with a
    one-line error here, not in the children."""
    from agents.anchoring import robot_offset, wrong_anchor_fault
    from agents.session import LinkFaults
    from polyswarm.explore.assign import Strategy

    try:
        Strategy(strategy)
    except ValueError:
        raise ConfigError(
            f"--strategy must be hungarian, greedy or nearest, not {strategy!r}"
        ) from None
    LinkFaults.parse(link_faults)
    wrong_anchor_fault(wrong_anchor)
    robot_offset(start_error, "start error")


def _live_table(opts, obs, wall: float):
    """The launch's live table: coverage, times and each robot's state."""
    from rich.table import Table

    cov = obs.coverage[-1][1] if obs.coverage else 0.0
    t = Table(
        title=(
            f"{opts.world}: {opts.robots} {opts.config.profile} robot(s), {opts.strategy} | "
            f"coverage {100 * cov:.1f} % | "
            f"sim {obs.sim_t:.0f} s | wall {wall:.0f} s | {obs.mission}"
        )
    )
    for col in ("robot", "state", "target", "keyframes", "path m", "bytes sent"):
        t.add_column(col, justify="right")
    for rid, v in obs.robots.items():
        t.add_row(
            rid,
            v.state,
            str(v.target),
            str(v.keyframes),
            f"{v.path_length_m:.1f}",
            f"{v.bytes_sent:,}",
        )
    return t


def _results_table(m: dict):
    """The launch's results: coverage, t99, IoU, bytes, faults."""
    from rich.table import Table

    table = Table(title=f"exploration of {m['world']} ({m['stopped_because']})")
    table.add_column("metric")
    table.add_column("value", justify="right")

    def secs(v) -> str:
        return "never" if v is None else f"{v:.0f} s"

    for k, v in (
        ("final coverage", f"{100 * m['final_coverage']:.1f} %"),
        ("reachable area left unexplored", f"{m['unexplored_reachable_m2']:.1f} m2"),
        ("t90 / t99 (simulated)", f"{secs(m['t90_s'])} / {secs(m['t99_s'])}"),
        ("map IoU", f"{m['map_iou']:.3f}"),
        ("path length (all robots)", f"{m['total_path_length_m']:.0f} m"),
        ("collisions walls / robots", f"{m['collisions']['walls']} / {m['collisions']['robots']}"),
        ("bytes sent per robot", ", ".join(f"{b:,}" for b in m["bytes_sent_per_robot"].values())),
        (
            "robot map updates lost in transit, map fetches (bytes)",
            f"{m['robot_map_gaps']}, {m['robot_map_fetches']} ({m['robot_map_fetch_bytes']:,} B)",
        ),
        ("wall time", f"{m['wall_time_s']:.0f} s"),
        ("crashed processes", ", ".join(m["crashed_processes"]) or "none"),
        ("restarted processes", ", ".join(f"{k} x{n}" for k, n in m["restarts"].items()) or "none"),
    ):
        table.add_row(k, v)
    for rid, a in m["anchors"].items():  # robots whose starts nobody gave
        table.add_row(
            f"{rid}'s frame found (simulated s, error)",
            f"{a['t_s']:.0f} s, {a['err_m']:.3f} m, {a['err_deg']:.2f} deg",
        )
    undone = [e["robot"] for e in m.get("anchor_events", []) if e["own"]]
    if undone:
        table.add_row("merges undone (frames withdrawn)", ", ".join(undone))
    if m["unanchored"]:
        table.add_row("frames never found", ", ".join(m["unanchored"]))
    return table


# the options of launch that need a paragraph of help
FAULT_OPT = typer.Option(
    "",
    help="Inject faults: action:process@simulated-seconds, comma separated; actions "
    "kill, stop, cont, restart (e.g. kill:r2@20,restart:r2@30); with --netns also cut "
    "and restore a host's link.",
)

LINK_FAULTS_OPT = typer.Option(
    "",
    help="Lose, duplicate and reorder received messages at the coordinator and agents "
    "(probabilities), e.g. drop=0.1,dup=0.05,reorder=0.05.",
)

WRONG_ANCHOR_OPT = typer.Option(
    "",
    help="With --unknown-start, a fault injection: commit ROBOT's first frame DX metres, "
    "DY metres and DEG degrees off (ROBOT:DX,DY,DEG, e.g. r2:2,1,20); its merge is undone "
    "once the robots' sightings contradict it.",
)

START_ERROR_OPT = typer.Option(
    "",
    help="Tell the swarm ROBOT's start DX metres, DY metres and DEG degrees off where it "
    "stands (ROBOT:DX,DY,DEG, e.g. r2:0.3,-0.2,3): a start measured badly; the joint pose "
    "graph pulls its map onto the others'.",
)

RESTART_OPT = typer.Option(
    True,
    help="Restart a process that exits unexpectedly, with backoff, as systemd would on a "
    "robot (--no-restart: stop the mission instead, for debugging).",
)

VIEW_PORT_OPT = typer.Option(
    None,
    "--view",
    min=0,
    max=65535,
    help="Also serve the live view in a browser on this port of 127.0.0.1 (polyswarm view).",
)

UNKNOWN_START_OPT = typer.Option(
    False,
    "--unknown-start",
    help="Place the robots at scattered random starts (seeded, 10 m apart where the world "
    "allows, random headings) and tell nobody: the coordinator finds each robot's frame by "
    "matching its map with the merged map (the first robot's start is the map's origin).",
)

NETNS_OPT = typer.Option(
    False,
    "--netns",
    help="Each robot and the coordinator on a host of its own: a network namespace whose "
    "only link to the others is wifi0 on one bridge; Zenoh routers in a mesh (needs root). "
    "Cut links with --fault cut:r1@60,restore:r1@120.",
)

COORDINATORS_OPT = typer.Option(
    1,
    min=1,
    max=9,
    help="Coordinators: the first active, the others (coordinator2, ...) standing by to "
    "take over when it is gone (e.g. --fault kill:coordinator@60,cut:coordinator@60).",
)


@app.command("launch")
def launch_cmd(
    robots: int = typer.Option(3, min=1, max=20, help="Number of robots."),
    world: str = typer.Option(
        "office", help="Procedural world name, data:NAME (../shared/data/worlds) or a .yaml."
    ),
    strategy: str = typer.Option("hungarian", help="hungarian, greedy or nearest."),
    seed: int = typer.Option(0, help="Seed of the sensor and odometry noise (and maze)."),
    speed: float = typer.Option(
        10.0, help="Simulated seconds per wall second, at most (0: as fast as possible)."
    ),
    gui: bool = typer.Option(False, "--gui", help="Show the pybullet GUI (needs a display)."),
    time_limit: float = typer.Option(
        math.inf, "--time-limit", help="Stop after this many simulated seconds."
    ),
    wall_limit: float = typer.Option(
        math.inf, "--wall-limit", help="Stop after this many wall-clock seconds."
    ),
    stop_coverage: float = typer.Option(
        0.0, help="Stop once this fraction of the free space is explored (0: at mission end)."
    ),
    out: Path | None = typer.Option(None, help="Run folder (default runs/<timestamp>/)."),
    config: Path | None = CONFIG_OPT,
    profile: str | None = typer.Option(None, help=PROFILE_HELP),
    fault: str = FAULT_OPT,
    link_faults: str = LINK_FAULTS_OPT,
    wrong_anchor: str = WRONG_ANCHOR_OPT,
    start_error: str = START_ERROR_OPT,
    restart: bool = RESTART_OPT,
    view_port: int | None = VIEW_PORT_OPT,
    unknown_start: bool = UNKNOWN_START_OPT,
    netns: bool = NETNS_OPT,
    coordinators: int = COORDINATORS_OPT,
) -> None:
    """Explore a simulated world with N robots: coordinator, sim and agents as processes.

    Ctrl-C, SIGTERM or SIGHUP (also when launched in the background, where the shell
    ignores SIGINT) stops every process and still writes the run folder."""
    from rich.console import Console
    from rich.live import Live

    from agents.session import stop_on_signals
    from polyswarm.runners.launch import Fault, LaunchOptions, launch

    _check_launch_args(strategy, link_faults, wrong_anchor, start_error)
    opts = LaunchOptions(
        world,
        robots,
        strategy,
        seed,
        speed,
        gui,
        time_limit,
        wall_limit,
        stop_coverage,
        out,
        load_cfg(config, profile),
        faults=Fault.parse_many(fault),
        link_faults=link_faults,
        wrong_anchor=wrong_anchor,
        view_port=view_port,
        restart=restart,
        unknown_start=unknown_start,
        start_error=start_error,
        netns=netns,
        coordinators=coordinators,
    )
    console = Console(stderr=True)
    if view_port is not None:
        console.print(f"live view: http://127.0.0.1:{view_port}/")

    stop = stop_on_signals(hangup=True)  # the launch ends as at its limits: outputs written
    with Live(console=console, refresh_per_second=2, transient=False) as live:
        res = launch(
            opts, progress=lambda obs, wall: live.update(_live_table(opts, obs, wall)), stop=stop
        )
    m = res.metrics
    Console().print(_results_table(m))
    typer.echo(f"wrote {res.out}", err=True)
    if m["crashed_processes"]:  # a process that died for good fails the launch
        raise SimulationError(f"process(es) died for good: {', '.join(m['crashed_processes'])}")


@app.command("fleet-config")
def fleet_config_cmd(
    robots: str = typer.Option(..., help="Robot ids, comma separated (e.g. r1,r2,r3)."),
    swarm: str = typer.Option("lab", help="Swarm name (the key prefix polyswarm/<swarm>)."),
    listen: str = typer.Option(
        "tls/0.0.0.0:7447", help="Endpoint the coordinator's router listens on."
    ),
    users_file: str = typer.Option("/etc/polyswarm/users.txt", help="user:password lines."),
    certs: str = typer.Option("/etc/polyswarm/certs", help="Folder of ca.pem, router.pem, ..."),
    mtls: bool = typer.Option(True, help="Require client certificates (mTLS)."),
    out: Path = typer.Option(Path("."), help="Folder for the JSON5 files."),
) -> None:
    """Write Zenoh configs of a secured fleet: router (TLS, users, ACL) and one per robot."""
    import json

    from agents.fleet import client_config, router_config

    ids = [r for r in robots.split(",") if r]
    if not ids or len(set(ids)) != len(ids):
        raise ConfigError(f"--robots {robots!r}: give distinct robot ids, comma separated")
    tls = {
        "root_ca_certificate": f"{certs}/ca.pem",
        "listen_certificate": f"{certs}/router.pem",
        "listen_private_key": f"{certs}/router-key.pem",
        "enable_mtls": mtls,
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "zenoh-router.json5").write_text(
        json.dumps(router_config(swarm, ids, listen, users_file, tls), indent=2)
    )
    connect = listen.replace("0.0.0.0", "coordinator.local")
    for rid in ids:
        ctls = {"root_ca_certificate": f"{certs}/ca.pem", "enable_mtls": mtls}
        if mtls:
            ctls |= {
                "connect_certificate": f"{certs}/{rid}.pem",
                "connect_private_key": f"{certs}/{rid}-key.pem",
            }
        conf = client_config(connect, rid, f"<password of {rid} in {users_file}>", ctls)
        (out / f"zenoh-{rid}.json5").write_text(json.dumps(conf, indent=2))
    typer.echo(f"wrote {out}/zenoh-router.json5 and zenoh-<id>.json5 for {', '.join(ids)}")


@app.command("router")
def router_cmd(
    listen: str = typer.Option(
        "tcp/127.0.0.1:7447", help="Endpoints to listen on (comma separated)."
    ),
    zenoh_config: Path | None = typer.Option(None, help=ZENOH_HELP),
) -> None:
    """Run a bare Zenoh router (no coordinator): the others connect to it as clients.

    With its own router a fleet keeps talking while the coordinator restarts."""
    import logging

    from agents.session import open_session, stop_on_signals

    stop = stop_on_signals()
    spec = session_spec(listen, None, str(zenoh_config or ""), listen, router=True)
    with open_session(spec):
        logging.getLogger("polyswarm.router").info("router listening on %s", listen)
        while not stop.wait(0.5):
            pass
