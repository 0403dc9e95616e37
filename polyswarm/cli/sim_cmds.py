"""``polyswarm sim``: look at the simulator, or serve it on Zenoh (``--serve``)."""

from __future__ import annotations

from pathlib import Path

import typer

from polyswarm.cli import PROFILE_HELP, app, load_cfg

WORLD_HELP = (
    "Procedural world (loop, cross, zigzag, maze, office, curves, rooms), "
    "data:NAME (../shared/data/worlds), or a map_server .yaml."
)


@app.command("sim")
def sim_cmd(
    world: str = typer.Option("office", help=WORLD_HELP),
    robots: int = typer.Option(1, min=1, help="Number of robots."),
    duration: float = typer.Option(60.0, "--time-limit", help="Simulated seconds to run."),
    seed: int = typer.Option(0, help="Seed for noise, procedural maze and wandering."),
    gui: bool = typer.Option(False, "--gui", help="Open the pybullet GUI (needs a display)."),
    out: Path | None = typer.Option(None, help="Write a PNG of the world and trajectories here."),
    config: Path | None = typer.Option(None, help="TOML config (its sim table is used)."),
    profile: str | None = typer.Option(None, help=PROFILE_HELP),
    serve: bool = typer.Option(
        False, "--serve", help="Serve on Zenoh: publish scans and odometry, obey cmd_vel."
    ),
    speed: float | None = typer.Option(
        None, help="--serve: simulated seconds per wall second (0: as fast as agents allow)."
    ),
    connect: str | None = typer.Option(
        None, help="--serve: Zenoh router to connect to (default: comms.endpoint)."
    ),
    zenoh_config: Path | None = typer.Option(None, help="--serve: Zenoh JSON5 config file."),
    wait_coordinator: bool = typer.Option(
        False, help="--serve: start time only once the coordinator is up (as well as agents)."
    ),
    robot_link: str = typer.Option(
        "",
        help="--serve: robots reached over links of their own, ROBOT=ENDPOINT comma separated "
        "(e.g. r1=unixsock-stream/run/r1.sock): their sensors are on board.",
    ),
) -> None:
    """Drive robots with a reactive wander controller and report what happened; with
    --serve, run the simulation for robot agents over Zenoh (robots from the config's
    robots table, else --robots spread over the start area)."""
    import time

    import numpy as np
    from rich.console import Console
    from rich.progress import Progress
    from rich.table import Table

    from polyswarm.config import with_overrides
    from sim import Simulation, load_world
    from sim.wander import Wander

    cfg = with_overrides(load_cfg(config, profile), {"sim": {"seed": seed}})
    w = load_world(world, seed=seed)
    if serve:
        links = _robot_links(robot_link, str(zenoh_config or cfg.comms.zenoh_config or ""))
        _serve(cfg, w, robots, speed, connect, zenoh_config, gui, wait_coordinator, links)
        return
    trails: list[list] = [[] for _ in range(robots)]
    t0 = time.perf_counter()
    with Simulation(w, cfg.sim, robots, gui=gui) as sim:
        ctl = [Wander(seed + k) for k in range(robots)]
        with Progress(transient=True, console=Console(stderr=True)) as prog:
            task = prog.add_task("simulating", total=duration)
            for ev in sim.run(duration):
                sim.set_cmd(ev.robot, *ctl[ev.robot].command(ev.scan))
                trails[ev.robot].append(ev.true_pose[:2])
                if gui:
                    time.sleep(sim.cfg.lidar.rate_hz**-1 / max(robots, 1) / 4)
                prog.update(task, completed=sim.time)
        wall = time.perf_counter() - t0
        table = Table(title=f"{w.name}: {duration:g} s simulated in {wall:.1f} s")
        for col in ("robot", "distance m", "wall contacts", "robot contacts"):
            table.add_column(col, justify="right")
        for r in sim.robots:
            table.add_row(
                r.name, f"{r.distance_m:.1f}", str(r.wall_collisions), str(r.robot_collisions)
            )
        Console().print(table)
    if out is not None:
        plot_world(w, [np.array(t) for t in trails], out)
        typer.echo(f"wrote {out}")


def plot_world(world, trajectories, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import shapely

    fig, ax = plt.subplots(figsize=(8, 8))
    ax.set_facecolor("#9e9e9e")
    for g in shapely.get_parts(world.free):
        ax.fill(*g.exterior.xy, color="white")
        for h in g.interiors:
            ax.fill(*h.xy, color="#9e9e9e")
    for t in trajectories:
        if len(t) > 1:
            ax.plot(t[:, 0], t[:, 1], linewidth=1)
    ax.set_aspect("equal")
    ax.set_title(world.name)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _robot_links(text: str, zconf: str) -> dict:
    """``r1=ENDPOINT,r2=ENDPOINT`` as each robot's client session; ConfigError when bad."""
    from agents.session import SessionSpec
    from polyswarm.errors import ConfigError

    links = {}
    for item in filter(None, (t.strip() for t in text.split(","))):
        rid, sep, endpoint = item.partition("=")
        if not sep or not rid or not endpoint:
            raise ConfigError(f"--robot-link {item!r}: expected ROBOT=ENDPOINT")
        links[rid] = SessionSpec.client(endpoint, zconf)
    return links


def _serve(
    cfg,
    world,
    robots: int,
    speed,
    connect,
    zenoh_config,
    gui: bool,
    wait_coordinator: bool,
    links: dict,
) -> None:
    import dataclasses

    from agents.session import SessionSpec, stop_on_signals
    from polyswarm.config import RobotEntry
    from polyswarm.runners.simserve import serve
    from sim import spread_start_poses

    if not cfg.robots:  # no [[robots]] in the config: r1..rN spread over the start area
        starts = spread_start_poses(world, robots, cfg.sim.robot.radius_m)
        cfg = dataclasses.replace(
            cfg, robots=tuple(RobotEntry(f"r{k + 1}", tuple(p)) for k, p in enumerate(starts))
        )
    spec = SessionSpec.client(
        connect or cfg.comms.endpoint, str(zenoh_config or cfg.comms.zenoh_config or "")
    )
    wait_for = ("agents", "coordinator") if wait_coordinator else ("agents",)
    sim = serve(
        cfg,
        world,
        spec,
        stop_on_signals(),
        speed=speed,
        gui=gui,
        wait_for=wait_for,
        robot_links=links,
    )
    typer.echo(
        f"simulated {sim.time:.1f} s; wall contacts "
        f"{sum(r.wall_collisions for r in sim.robots)}, robot contacts "
        f"{sum(r.robot_collisions for r in sim.robots)}",
        err=True,
    )
