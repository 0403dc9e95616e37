"""``polyswarm slam``: offline PolySLAM on a CARMEN log or a simulated world."""

from __future__ import annotations

from pathlib import Path

import typer

from polyswarm.cli import PROFILE_HELP, app, load_cfg
from polyswarm.errors import DataFormatError, PolyswarmError


@app.command("slam")
def slam_cmd(
    log: Path | None = typer.Argument(None, help="CARMEN log (.log or .log.gz)."),
    world: str | None = typer.Option(
        None,
        help="Instead of a log: a world to drive through (procedural name, data:NAME or .yaml).",
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder."),
    seed: int = typer.Option(0, help="Seed of the odometry (and sensor) noise."),
    odometry: str = typer.Option(
        "log",
        help="Logs: 'log' = the robot's real wheel odometry (its ODOM lines), 'noise' = "
        "synthetic noise on the corrected poses' increments (seeded; for logs without "
        "raw odometry, and stress tests).",
    ),
    odom_noise: float = typer.Option(
        1.0, "--odom-noise", help="Logs, --odometry noise: multiply the default noise by this."
    ),
    speed: float = typer.Option(1.0, help="Worlds: driving speed along the route, m/s."),
    config: Path | None = typer.Option(None, help="TOML config."),
    profile: str | None = typer.Option(None, help="Worlds: " + PROFILE_HELP),
) -> None:
    """Run PolySLAM; write map.polymap/.svg/.png, trajectory.tum, config.toml, metrics.json."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn
    from rich.table import Table

    from polyswarm.odometry import IncrementNoise
    from polyswarm.runners import slam as runner

    if (log is None) == (world is None):
        raise PolyswarmError("give either a LOG or --world (not both)")
    if log is not None and profile is not None:
        raise PolyswarmError("--profile is for --world runs: a log brings its own sensor")
    cfg = load_cfg(config, profile)
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>3.0f}%"),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=True,
    ) as prog:
        task = prog.add_task("PolySLAM", total=1.0)

        def report(done: float, total: float) -> None:
            prog.update(task, completed=done, total=total)

        if log is not None:
            n = IncrementNoise()
            noise = IncrementNoise(
                *(
                    odom_noise * v
                    for v in (
                        n.scale_sigma,
                        n.lateral_sigma_per_m,
                        n.heading_sigma_per_rad,
                        n.heading_sigma_per_m,
                    )
                )
            )
            try:
                source = runner.OdometrySource(odometry)
            except ValueError:
                raise PolyswarmError(
                    f"--odometry must be one of {[str(o) for o in runner.OdometrySource]}"
                ) from None
            try:
                run = runner.run_log(log, cfg, noise, seed, report, source)
            except DataFormatError as e:
                if source != runner.OdometrySource.LOG or "ODOM" not in str(e):
                    raise
                raise DataFormatError(f"{e}; run with --odometry noise") from None
        else:
            run = runner.run_world(world, cfg, seed, speed, report)
    m = runner.write_outputs(run, out, cfg)
    t = Table(title=f"PolySLAM on {run.name}")
    t.add_column("metric")
    t.add_column("value", justify="right")
    rows = [
        ("distance travelled", f"{m['distance_travelled_m']:.1f} m"),
        (
            "ATE RMSE (odometry alone)",
            f"{m['ate_rmse_m']:.3f} m ({m['odometry_ate_rmse_m']:.3f} m)",
        ),
        (
            "RPE over 1 m / 10 m",
            f"{m['rpe_1m_trans_mean_m']:.3f} / {m['rpe_10m_trans_mean_m']:.3f} m",
        ),
        ("max error", f"{m['max_trans_error_m']:.3f} m, {m['max_rot_error_deg']:.2f} deg"),
        ("max error / distance", f"{100 * m['max_trans_error_ratio']:.3f} %"),
        ("keyframes, p95 time", f"{m['keyframes']}, {m['keyframe_p95_ms']:.1f} ms"),
        ("faster than real time", f"{m['realtime_factor']:.1f} x"),
        ("map vectors / polygons", f"{m['vectors']} / {m['polygons']}"),
    ]
    if "map_iou" in m:
        rows.append(
            ("map IoU, wall distance", f"{m['map_iou']:.3f}, {m['wall_distance_mean_m']:.3f} m")
        )
    for r in rows:
        t.add_row(*r)
    Console().print(t)
    typer.echo(f"wrote {out}")
