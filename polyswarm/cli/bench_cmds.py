"""``polyswarm bench NAME [--json]``: benchmarks with a table or machine-readable output."""

from __future__ import annotations

import json
import math

import typer

from polyswarm.cli import bench_app

JSON_OPT = typer.Option(False, "--json", help="Print JSON instead of a table.")
SAVE_OPT = typer.Option(
    None,
    "--save",
    metavar="NAME",
    help="Also write the result to docs/results/NAME.json, with the code version, the "
    "processor, the date and the command.",
)


def _names(text: str) -> tuple[str, ...]:
    """The names of a comma-separated option (``office,data:maze``), empty ones left out."""
    return tuple(n for n in text.split(",") if n)


def _save(name: str | None, result: dict) -> None:
    if name:
        from polyswarm.benchmarks.results import save

        typer.echo(f"wrote {save(name, result)}", err=True)


def _emit(result: dict, as_json: bool, title: str, rows: list[tuple[str, str]]) -> None:
    if as_json:
        typer.echo(json.dumps(result, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title)
    table.add_column("metric")
    table.add_column("value", justify="right")
    for k, v in rows:
        table.add_row(k, v)
    Console().print(table)


@bench_app.command("format")
def bench_format(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    cell_size: float = typer.Option(2.0, help="Cell size, metres."),
) -> None:
    """PolyMap bytes against PNG/zlib of the same 5 cm grid, the PNG at the map's own
    resolution, and a 5 cm grid built from noisy scans along a route; merge latency."""
    from rich.console import Console
    from rich.table import Table

    from polyswarm.benchmarks import format as fmt

    console = Console(stderr=True)
    with console.status("converting worlds and merging keyframes"):
        res = fmt.run(cell_size)
    _save(save, res)
    if as_json:
        typer.echo(json.dumps(res, indent=2))
        return
    t = Table(
        title=f"PolyMap format ({fmt.GRID_RESOLUTION_M * 100:.0f} cm grids, {cell_size:g} m cells)"
    )
    for col in (
        "world",
        "vectors",
        "polygons",
        "bytes",
        "zlib",
        "PNG",
        "grid zlib",
        "bytes/PNG",
        "bytes/native PNG",
        "route: bytes/PNG",
        "free kept",
        "occ kept",
    ):
        t.add_column(col, justify="right")
    for name, w in res["worlds"].items():
        t.add_row(
            name,
            str(w["vectors"]),
            str(w["polygons"]),
            str(w["encoded_bytes"]),
            str(w["encoded_zlib_bytes"]),
            str(w["grid_png_bytes"]),
            str(w["grid_zlib_bytes"]),
            f"{w['encoded_bytes'] / w['grid_png_bytes']:.2f}",
            f"{w['bytes_ratio_vs_native_png']:.2f}",
            f"{w['route_bytes_ratio_vs_png']:.2f}",
            f"{w['round_trip_free_kept']:.4f}",
            f"{w['round_trip_occupied_kept']:.4f}",
        )
    Console().print(t)
    _emit(
        res,
        False,
        "merge",
        [
            (
                "keyframes (vectors)",
                f"{res['keyframes']} ({res['keyframe_vectors_min']}-{res['keyframe_vectors_max']})",
            ),
            ("final map vectors", str(res["final_map_vectors"])),
            ("merge p50", f"{res['merge_p50_ms']:.2f} ms"),
            ("merge p95", f"{res['merge_p95_ms']:.2f} ms"),
            ("bytes per vector", f"{res['bytes_per_vector']:.2f}"),
        ],
    )


@bench_app.command("sim")
def bench_sim(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    world: str = typer.Option("data:maze", help="World to step (default: the largest)."),
) -> None:
    """Lidar scans per second, real-time factor against ray casting alone, memory."""
    from rich.console import Console

    from polyswarm.benchmarks import sim as simbench

    with Console(stderr=True).status(f"stepping {world}"):
        res = simbench.run(world)
    _save(save, res)
    rows = [(f"scans/s, {n} robot(s)", f"{v:.0f}") for n, v in res["scans_per_s"].items()]
    rows += [
        ("real-time factor, 3 robots", f"{res['real_time_factor_3_robots']:.1f}"),
        ("ray casting only bound", f"{res['raycast_only_real_time_factor_3_robots']:.1f}"),
        ("share of step not ray casting", f"{100 * res['non_raycast_fraction_3_robots']:.0f} %"),
        (
            "real-time factor, ray casting on one thread",
            f"{res['real_time_factor_3_robots_one_raycast_thread']:.1f}",
        ),
        ("peak memory", f"{res['peak_memory_mb']:.0f} MB"),
    ]
    _emit(res, as_json, f"simulator on {res['world']} ({res['beams']} beams)", rows)


@bench_app.command("ros2")
def bench_ros2(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    duration: float = typer.Option(
        30.0, "--wall-limit", min=5.0, help="Wall-clock seconds of lidar stream per path."
    ),
) -> None:
    """The agent as a ROS 2 node (rclpy, Fast DDS) against the Zenoh path: CPU, map latency."""
    from rich.console import Console

    from polyswarm.benchmarks import ros2

    with Console(stderr=True).status("a 10 Hz 720-beam stream through each path"):
        res = ros2.run(duration)
    _save(save, res)
    rows = []
    for path, r in res["paths"].items():
        rows += [
            (f"{path}: scans mapped, of those sent", f"{100 * r['scans_processed']:.1f} %"),
            (f"{path}: SLAM, share of one core", f"{100 * r['slam_share']:.1f} %"),
            (
                f"{path}: beyond SLAM, share of one core",
                f"{100 * r['cpu_beyond_slam_share']:.1f} %",
            ),
        ]
        if "map_latency_p95_s" in r:
            rows.append(
                (f"{path}: map change to subscriber, p95", f"{r['map_latency_p95_s']:.3f} s")
            )
    _emit(res, as_json, "ROS 2 node against the Zenoh path", rows)


@bench_app.command("bags")
def bench_bags(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    shared: bool = typer.Option(True, help="Also the shared TurtleBot3 bag (../shared/data)."),
) -> None:
    """ROS bags through polyswarm slam (speed, sharpness, mount from tf) and agent replay."""
    from rich.console import Console

    from polyswarm.benchmarks import bags

    shared_bag = None
    if shared:
        from polyswarm.data import shared_data_dir

        shared_bag = shared_data_dir() / "bags" / "turtlebot3-gazebo.bag"
    with Console(stderr=True).status("bags through slam and agent replay"):
        res = bags.run(shared_bag)
    _save(save, res)
    rows = []
    for name, r in res["bags"].items():
        s, p = r["slam"], r["replay"]
        rows += [
            (f"{name}: scans, bag seconds", f"{s['scans']}, {s['duration_s']:.0f} s"),
            (f"{name}: slam faster than real time", f"{s['realtime_factor']:.1f} x"),
            (
                f"{name}: occupied 5 cm cells (odometry alone)",
                f"{s['occupied_cells_5cm']} ({s['odometry_occupied_cells_5cm']})",
            ),
            (f"{name}: mount from", s["mount"]),
            (
                f"{name}: agent replay at {p['rate']:g}x: scans, refused",
                f"{p['scans']}, {p['refused']}",
            ),
        ]
        if "mount_error_m" in s:
            rows.append(
                (
                    f"{name}: mount error",
                    f"{s['mount_error_m'] * 1000:.1f} mm, {math.degrees(s['mount_error_rad']):.2f} "
                    f"deg, upside down {'right' if s['mount_upside_down_matches'] else 'wrong'}",
                )
            )
    _emit(res, as_json, "ROS bags", rows)


@bench_app.command("view")
def bench_view(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    robots: int = typer.Option(10, min=1, help="Robots."),
    world: str = typer.Option("data:maze", help="World to explore."),
    duration: float = typer.Option(
        120.0, "--wall-limit", help="Wall-clock seconds of each of the two runs."
    ),
) -> None:
    """The live view: display latency, its CPU, the coordinator with and without it."""
    from rich.console import Console

    from polyswarm.benchmarks import view

    with Console(stderr=True).status(f"two {duration:.0f} s runs of {robots} robots"):
        res = view.run(robots, world, duration)
    _save(save, res)
    a, b = res["without_view"], res["with_view"]

    def ms(v):
        return "-" if v is None else f"{v:.0f} ms"

    rows = [
        ("display latency p95 (publication to page)", ms(res["display_latency_p95_ms"])),
        ("view process, share of one core", f"{100 * (res['view_cpu_share'] or 0):.1f} %"),
        (
            "coordinator cycle p95 without / with the view",
            f"{ms(a['coordinator_cycle_p95_ms'])} / {ms(b['coordinator_cycle_p95_ms'])}",
        ),
    ]
    _emit(res, as_json, f"live view: {robots} robots on {world}", rows)


@bench_app.command("lidar")
def bench_lidar(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    simulated: str = typer.Option(
        "neato,hokuyo,turtlebot4,turtlebot3",
        help="Profiles whose simulated lidar is measured too, on the office and furnished worlds.",
    ),
) -> None:
    """How real low-cost lidars fail, fitted on the shared recordings (by range, incidence,
    runs, mixed pixels, noise), and how the simulated profiles fail indoors."""
    from rich.console import Console

    from polyswarm.benchmarks import lidarfit
    from polyswarm.data import shared_data_dir

    with Console(stderr=True).status("fitting the shared recordings"):
        res = {"recordings": lidarfit.run(shared_data_dir() / "bags"), "simulated": {}}
        for profile in _names(simulated):
            res["simulated"][profile] = {
                w: lidarfit.simulated(profile, w) for w in ("office", "furnished")
            }
    _save(save, res)
    rows = []
    for name, r in res["recordings"].items():
        by_range = ", ".join(
            f"{k} m {100 * v['share']:.0f} %" for k, v in r["drop_by_range"].items() if v
        )
        by_inc = ", ".join(
            f"{k} deg {100 * v['share']:.0f} %" for k, v in r["drop_by_incidence_deg"].items() if v
        )
        rows += [
            (f"{name}: no return, all beams", f"{100 * r['no_return_share']:.0f} %"),
            (f"{name}: no return by range", by_range),
            (f"{name}: no return by incidence", by_inc),
            (
                f"{name}: invalid runs, median beams; mixed pixels at edges",
                f"{r['invalid_run_beams']['median']:.0f}; "
                f"{100 * (r['mixed_pixel_share_at_edges'] or 0):.1f} %",
            ),
        ]
    for profile, by in res["simulated"].items():
        for w, r in by.items():
            rows.append(
                (
                    f"simulated {profile}, {w}: no return; invalid runs, median beams",
                    f"{100 * r['no_return_share']:.0f} %; {r['invalid_run_beams_median']:.0f}",
                )
            )
    _emit(res, as_json, "Low-cost lidars, real and simulated", rows)


@bench_app.command("maps")
def bench_maps(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    worlds: str = typer.Option(
        "office,rooms,furnished,data:nav2-depot,data:nav2-warehouse",
        help="Simulated worlds, comma-separated ('' for none).",
    ),
    profiles: str = typer.Option(
        "thesis,turtlebot3,turtlebot4,hokuyo,neato", help="Robot profiles, comma-separated."
    ),
    recordings: bool = typer.Option(True, help="The shared recordings (../shared/data/bags)."),
    seed: int = typer.Option(0, help="Seed of the simulated sensors and odometry."),
) -> None:
    """Maps against their references: each shared recording's PolyMap against the
    log-odds grid of the same scans at the same poses; each simulated world and profile
    against the ground truth."""
    from rich.console import Console

    from polyswarm.benchmarks import maps

    bags = None
    if recordings:
        from polyswarm.data import shared_data_dir

        bags = shared_data_dir() / "bags"
    with Console(stderr=True).status("maps") as status:
        res = maps.run(bags, _names(worlds), _names(profiles), seed, status.update)
    _save(save, res)
    rows = []
    for name, r in res["recordings"].items():
        e, k = r["evidence"], r["keyframes_alone"]
        rows.append(
            (
                f"{name} ({r['lidar']}): wall recall, walls typed frontier, explored where "
                "no beam went, explored / grid free (keyframes alone)",
                f"{e['wall_recall']:.2f}, {100 * e['walls_as_frontier']:.1f} %, "
                f"{100 * e['explored_unseen_share']:.1f} %, {e['explored_over_free']:.2f} "
                f"({k['wall_recall']:.2f}, {100 * k['walls_as_frontier']:.1f} %, "
                f"{100 * k['explored_unseen_share']:.1f} %, {k['explored_over_free']:.2f})",
            )
        )
    for spec, by in res["worlds"].items():
        for profile, r in by.items():
            rows.append(
                (
                    f"{spec}, {profile}: IoU, ghost walls, explored beyond walls",
                    f"{r['map_iou']:.3f}, {100 * r['ghost_walls']:.1f} %, "
                    f"{100 * r['explored_beyond_walls']:.1f} %",
                )
            )
    _emit(res, as_json, "Maps against their references", rows)
