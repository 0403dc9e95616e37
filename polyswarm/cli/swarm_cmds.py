"""``polyswarm agent``, ``polyswarm coordinator`` and ``polyswarm launch``."""

from __future__ import annotations

import math
from pathlib import Path

import typer

from polyswarm.cli import app
from polyswarm.errors import ConfigError

CONFIG_OPT = typer.Option(None, "--config", "-c", help="TOML config file.")
ENDPOINT_HELP = "Zenoh endpoint of the router (default: comms.endpoint of the config)."
ZENOH_HELP = "Zenoh JSON5 config file (LAN, TLS, ACL); --endpoint still applies."


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


@app.command("agent")
def agent_cmd(
    robot_id: str = typer.Option(..., "--id", help="Robot id (a key chunk, e.g. r1)."),
    config: Path | None = CONFIG_OPT,
    endpoint: str | None = typer.Option(None, help=ENDPOINT_HELP),
    zenoh_config: Path | None = typer.Option(None, help=ZENOH_HELP),
    start: str | None = typer.Option(
        None, help="Start pose x,y,theta (metres, radians) in the shared map frame."
    ),
    duration: float = typer.Option(0.0, help="Stop after this many wall seconds (0: run)."),
) -> None:
    """Run a robot agent: PolySLAM, map deltas, planning and local control over Zenoh."""
    import logging

    from agents.robot import run_agent
    from agents.session import SessionSpec
    from polyswarm.config import load_config
    from protocols.keys import check_name

    check_name(robot_id, "robot id")
    cfg = load_config(config)
    pose = _pose(start)
    if pose is None:
        entry = next((r for r in cfg.robots if r.id == robot_id), None)
        if entry is None:
            logging.getLogger("polyswarm").warning(
                "no start pose for %s (no --start, not in [[robots]]): using (0, 0, 0)", robot_id
            )
            pose = (0.0, 0.0, 0.0)
        else:
            pose = tuple(entry.start)
    spec = SessionSpec.client(
        endpoint or cfg.comms.endpoint, str(zenoh_config or cfg.comms.zenoh_config or "")
    )
    agent = run_agent(robot_id, cfg, pose, spec, duration_s=duration)
    s = agent.stats
    typer.echo(
        f"{robot_id}: {s.scans} scans, {s.keyframes} keyframes, {s.distance_m:.1f} m, "
        f"{agent.bytes_sent} bytes sent",
        err=True,
    )


@app.command("coordinator")
def coordinator_cmd(
    config: Path | None = CONFIG_OPT,
    listen: str | None = typer.Option(
        None, help="Endpoint the built-in Zenoh router listens on (default: comms.endpoint)."
    ),
    zenoh_config: Path | None = typer.Option(None, help=ZENOH_HELP),
    strategy: str | None = typer.Option(None, help="hungarian, greedy or nearest."),
) -> None:
    """Run the coordinator (and the Zenoh router): merged map, frontiers, assignment."""
    from agents.coordinator import run_coordinator
    from agents.session import SessionSpec
    from polyswarm.config import load_config, with_overrides

    cfg = load_config(config)
    if strategy is not None:
        cfg = with_overrides(cfg, {"explore": {"strategy": strategy}})
    spec = SessionSpec.router(
        listen or cfg.comms.endpoint, str(zenoh_config or cfg.comms.zenoh_config or "")
    )
    coord = run_coordinator(cfg, spec)
    typer.echo(
        f"coordinator: mission {coord.state}, merged map {coord.merged.explored_area():.1f} m2, "
        f"{coord.bytes_sent} bytes sent",
        err=True,
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
) -> None:
    """Explore a simulated world with N robots: coordinator, sim and agents as processes."""
    import threading

    from rich.console import Console
    from rich.live import Live
    from rich.table import Table

    from polyswarm.config import load_config
    from polyswarm.explore import Strategy
    from polyswarm.runners.launch import LaunchOptions, launch

    try:
        Strategy(strategy)
    except ValueError:
        raise ConfigError(
            f"--strategy must be hungarian, greedy or nearest, not {strategy!r}"
        ) from None
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
        load_config(config),
    )
    console = Console(stderr=True)

    def view(obs, wall: float) -> Table:
        cov = obs.coverage[-1][1] if obs.coverage else 0.0
        t = Table(
            title=(
                f"{world}: {robots} robot(s), {strategy} | coverage {100 * cov:.1f} % | "
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

    stop = threading.Event()
    with Live(console=console, refresh_per_second=2, transient=False) as live:
        try:
            res = launch(opts, progress=lambda obs, wall: live.update(view(obs, wall)), stop=stop)
        except KeyboardInterrupt:
            stop.set()
            raise
    m = res.metrics
    table = Table(title=f"exploration of {m['world']} ({m['stopped_because']})")
    table.add_column("metric")
    table.add_column("value", justify="right")

    def secs(v) -> str:
        return "never" if v is None else f"{v:.0f} s"

    for k, v in (
        ("final coverage", f"{100 * m['final_coverage']:.1f} %"),
        ("t90 / t99 (simulated)", f"{secs(m['t90_s'])} / {secs(m['t99_s'])}"),
        ("map IoU", f"{m['map_iou']:.3f}"),
        ("path length (all robots)", f"{m['total_path_length_m']:.0f} m"),
        ("collisions walls / robots", f"{m['collisions']['walls']} / {m['collisions']['robots']}"),
        ("bytes sent per robot", ", ".join(f"{b:,}" for b in m["bytes_sent_per_robot"].values())),
        ("wall time", f"{m['wall_time_s']:.0f} s"),
        ("crashed processes", ", ".join(m["crashed_processes"]) or "none"),
    ):
        table.add_row(k, v)
    Console().print(table)
    typer.echo(f"wrote {res.out}", err=True)
