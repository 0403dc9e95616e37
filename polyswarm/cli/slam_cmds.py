"""``polyswarm slam``: offline PolySLAM on a CARMEN log, a ROS bag or a simulated world."""

from __future__ import annotations

from pathlib import Path

import typer

from polyswarm.cli import PROFILE_HELP, app, load_cfg
from polyswarm.errors import DataFormatError, PolyswarmError


def _run_log(log: Path, cfg, odometry: str, odom_noise: float, seed: int, report):
    """PolySLAM over a CARMEN log, on its wheel odometry or on seeded synthetic noise
    (``odom_noise`` times the default)."""
    from polyswarm.runners import slam as runner
    from polyswarm.slam.odometry import IncrementNoise

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
        return runner.run_log(log, cfg, noise, seed, report, source)
    except DataFormatError as e:
        if source != runner.OdometrySource.LOG or "ODOM" not in str(e):
            raise
        raise DataFormatError(f"{e}; run with --odometry noise") from None


def _slam_table(name: str, m: dict):
    """The metrics of a SLAM run: accuracy where there is ground truth, the map's
    sharpness and the recording's facts for a bag, then cost."""
    from rich.table import Table

    t = Table(title=f"PolySLAM on {name}")
    t.add_column("metric")
    t.add_column("value", justify="right")
    rows = [("distance travelled", f"{m['distance_travelled_m']:.1f} m")]
    if "ate_rmse_m" in m:
        rows += [
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
        ]
    if "occupied_cells_5cm" in m:  # a bag: no ground truth, the map's sharpness instead
        rows += [
            (
                "occupied 5 cm cells (odometry alone)",
                f"{m['occupied_cells_5cm']} ({m['odometry_occupied_cells_5cm']})",
            ),
            ("lidar mount from", m["mount"]),
            ("mount check", m["mount_check"]["advice"] or "sharpest as given"),
            (
                "no return reported as",
                f"{m['no_return']} ({100 * m['no_return_share']:.0f} % of beams)",
            ),
            ("messages skipped", str(sum(m["skipped"].values()))),
        ]
    rows += [
        ("loops closed", str(m["loops_closed"])),
        ("odometry distance scale learnt", f"{m['odometry_scale']:.4f}"),
        ("keyframes, p95 time", f"{m['keyframes']}, {m['keyframe_p95_ms']:.1f} ms"),
        ("faster than real time", f"{m['realtime_factor']:.1f} x"),
        ("map vectors / polygons", f"{m['vectors']} / {m['polygons']}"),
    ]
    for r in rows:
        t.add_row(*r)
    return t


@app.command("slam")
def slam_cmd(
    log: Path | None = typer.Argument(
        None,
        help="CARMEN log (.log or .log.gz) or ROS bag (ROS 1 .bag; rosbag2 folder, .mcap or .db3).",
    ),
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
    profile: str | None = typer.Option(
        None,
        help="Worlds: the robot simulated; bags: the robot that recorded it (its SLAM "
        "values; default: those of a real low-cost lidar). " + PROFILE_HELP,
    ),
    scan_topic: str | None = typer.Option(
        None,
        help="Bags: the sensor_msgs/LaserScan topic (default: the only one, else the one "
        "named 'scan').",
    ),
    odom_topic: str | None = typer.Option(
        None, help="Bags: the nav_msgs/Odometry topic (default: the only one)."
    ),
    ros_distro: str = typer.Option(
        "humble",
        help="Bags: the ROS 2 distribution whose message definitions read a bag that has "
        "none (rosbag2 written before Iron).",
    ),
) -> None:
    """Run PolySLAM; write map.polymap/.svg/.png, trajectory.tum, config.toml, metrics.json."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    from polyswarm.runners import slam as runner
    from protocols.bags import is_bag

    if (log is None) == (world is None):
        raise PolyswarmError("give either a LOG or --world (not both)")
    if log is not None and not is_bag(log) and profile is not None:
        raise PolyswarmError(
            "--profile is for --world runs and bags: a CARMEN log brings its own sensor"
        )
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

        if log is not None and is_bag(log):
            run, cfg = runner.run_bag(log, cfg, report, scan_topic, odom_topic, ros_distro)
        elif log is not None:
            run = _run_log(log, cfg, odometry, odom_noise, seed, report)
        else:
            run = runner.run_world(world, cfg, seed, speed, report)
    m = runner.write_outputs(run, out, cfg)
    Console().print(_slam_table(run.name, m))
    typer.echo(f"wrote {out}")


@app.command("scan")
def scan_cmd(
    bag: Path = typer.Argument(..., help="ROS bag (ROS 1 .bag; rosbag2 folder, .mcap or .db3)."),
    index: int = typer.Option(0, min=0, help="Which scan (0: the first)."),
    out: Path = typer.Option(Path("scan.png"), "--out", "-o", help="Picture (.png or .svg)."),
    config: Path | None = typer.Option(None, help="TOML config ([slam.mount] overrides tf)."),
    scan_topic: str | None = typer.Option(None, help="The sensor_msgs/LaserScan topic."),
    odom_topic: str | None = typer.Option(None, help="The nav_msgs/Odometry topic."),
    ros_distro: str = typer.Option(
        "humble", help="The ROS 2 distribution whose message definitions read a bag without."
    ),
) -> None:
    """Check a lidar mount: one scan drawn in the robot's base frame (x forward, metres),
    with the mount polyswarm would use (tf, the config, or the default) printed.

    Park the robot facing a wall when recording: with the right mount the wall is a
    straight line ahead of the robot (+x), at the distance you measured."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from polyswarm.slam.scan import beam_angles, classify
    from protocols.bags import read_bag
    from protocols.tf import choose_mount

    cfg = load_cfg(config, None)
    data = read_bag(bag, scan_topic, odom_topic, ros_distro)
    if index >= len(data.scans):
        raise PolyswarmError(f"--index {index}: the bag has {len(data.scans)} scans")
    mount, source = choose_mount(cfg.slam.mount, data.mounts, str(bag))
    m = (mount.x_m, mount.y_m, mount.yaw_rad, mount.upside_down)
    scan = data.scans[index]
    valid = classify(scan)[0]
    r = np.asarray(scan.ranges, dtype=float)[valid]
    a = beam_angles(scan, m)[valid]
    x, y = m[0] + r * np.cos(a), m[1] + r * np.sin(a)
    fig, ax = plt.subplots(figsize=(6, 6))
    ax.scatter(x, y, s=2, c="tab:red", label=f"scan {index} ({valid.sum()} returns)")
    ax.add_patch(plt.Circle((0, 0), cfg.nav.robot_radius_m, fill=False, color="tab:blue"))
    ax.annotate("", (0.5, 0), (0, 0), arrowprops={"arrowstyle": "->", "color": "tab:blue"})
    ax.plot([m[0]], [m[1]], "k+", label="lidar")
    ax.set(aspect="equal", xlabel="x, forward (m)", ylabel="y, left (m)")
    ax.set_title(f"{data.base_frame or 'base'} frame, mount from {source}")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    side = "upside down" if mount.upside_down else "upright"
    typer.echo(
        f"mount from {source}: x {mount.x_m:.3f} m, y {mount.y_m:.3f} m, "
        f"yaw {mount.yaw_rad:.3f} rad, {side} ({data.base_frame or '?'} -> "
        f"{data.scan_frame or '?'})"
    )
    if len(r):
        ahead = (np.abs(np.arctan2(y, x)) < 0.1) & (x > 0)
        if ahead.any():
            typer.echo(f"nearest return straight ahead: {x[ahead].min():.2f} m")
    typer.echo(f"wrote {out}")
