"""``polyswarm bench NAME [--json]``: benchmarks with a table or machine-readable output."""

from __future__ import annotations

import json
import math
from pathlib import Path

import typer

from polyswarm.cli import app, bench_app

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
    duration: float = typer.Option(30.0, min=5.0, help="Seconds of lidar stream per path."),
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
    duration: float = typer.Option(120.0, help="Wall-clock seconds of each of the two runs."),
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


def _live_row(name: str, m: dict) -> tuple[str, str]:
    """The map shared as it went against the map at the final poses."""
    return (
        f"{name}: live map vs rebuilt, IoU / ghost walls",
        f"{m['live_vs_rebuilt_iou']:.3f} / {100 * m['ghost_wall_share']:.1f} %",
    )


def _correction_row(name: str, m: dict) -> tuple[str, str]:
    """Loop corrections of the map: how many, and their p95 beside the keyframes'."""
    if not m.get("corrections"):
        return (f"{name}: map corrections", "none")
    return (
        f"{name}: map corrections, p95 (keyframe p95)",
        f"{m['corrections']}, {m['correction_p95_ms']:.0f} ms ({m['keyframe_p95_ms']:.0f} ms)",
    )


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


@bench_app.command("slam")
def bench_slam(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    worlds: str = typer.Option("loop,cross,zigzag,maze", help="Thesis worlds to drive through."),
    log_seeds: int = typer.Option(
        1, min=1, help="Odometry-noise seeds per log (0..N-1); ATE median and max over them."
    ),
) -> None:
    """PolySLAM on the thesis' worlds and the real logs; refinement; speed (minutes)."""
    from rich.console import Console

    from polyswarm.benchmarks import slam as slambench

    console = Console(stderr=True)
    with console.status("PolySLAM") as status:
        res = slambench.run(
            lambda what: status.update(f"PolySLAM: {what}"),
            _names(worlds),
            log_seeds,
        )
    _save(save, res)
    if as_json:
        typer.echo(json.dumps(res, indent=2, default=float))
        return
    rows = []
    for w, m in res["worlds"].items():
        ours, thesis = 100 * m["max_trans_error_ratio"], 100 * m["thesis_max_trans_error_ratio"]
        rows.append((f"{w}: max error / distance (thesis)", f"{ours:.3f} % ({thesis:.3f} %)"))
        rows.append((f"{w}: map IoU, polygons", f"{m['map_iou']:.3f}, {m['polygons']}"))
        rows.append(_live_row(w, m))
        rows.append(_correction_row(w, m))
    for name, m in res["logs"].items():
        real = m.get("real_odometry")
        src = "real odometry" if real is not None else "synthetic noise"
        rows.append(_live_row(f"log {name} ({src})", real or m))
        rows.append(_live_row(f"log {name} ({src}), a map that only grows", (real or m)["growing"]))
        rows.append(_correction_row(f"log {name} ({src})", real or m))
        rows.append(
            (
                f"log {name}: ATE (odometry), synthetic noise",
                f"{m['ate_rmse_m']:.3f} m ({m['odometry_ate_rmse_m']:.3f} m)",
            )
        )
        real = m.get("real_odometry")
        rows.append(
            (
                f"log {name}: ATE (odometry), real wheel odometry",
                "none in the log"
                if real is None
                else f"{real['ate_rmse_m']:.3f} m ({real['odometry_ate_rmse_m']:.3f} m)",
            )
        )
        if len(m["ate_rmse_m_by_seed"]) > 1:
            rows.append(
                (
                    f"log {name}: ATE median / max over {len(m['ate_rmse_m_by_seed'])} seeds",
                    f"{m['ate_rmse_median_m']:.3f} / {m['ate_rmse_max_m']:.3f} m",
                )
            )
    for name, m in res["refinement_curves"].items():
        rows.append(
            (
                f"curves {name}: vectors, farthest point",
                f"{m['vectors_max']}, {m['farthest_point_m_max']:.3f} m",
            )
        )
    rows.append(
        ("keyframe p50 / p95", f"{res['keyframe_p50_ms']:.1f} / {res['keyframe_p95_ms']:.1f} ms")
    )
    if "keyframe_p95_ms_720_beams" in res:
        rows.append(("keyframe p95, 720-beam scans", f"{res['keyframe_p95_ms_720_beams']:.1f} ms"))
        for stage, v in res["keyframe_stage_ms_720_beams"].items():
            rows.append((f"  {stage} p50 / p95", f"{v['p50']:.1f} / {v['p95']:.1f} ms"))
    rows.append(("real-time factor (worst world)", f"{res['realtime_factor_min']:.1f} x"))
    _emit(res, False, "PolySLAM", rows)


@bench_app.command("nav")
def bench_nav(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    pairs: int = typer.Option(50, min=1, help="Random start/goal pairs per map."),
    seed: int = typer.Option(0, help="Seed of the start/goal draw and the PolySLAM run."),
) -> None:
    """Navigation graph and planner against shortest paths on the inflated grid: scikit-image's
    compiled planner at 5 cm and at the map's own resolution, and a Python A*."""
    from rich.console import Console

    from polyswarm.benchmarks import nav as navbench

    with Console(stderr=True).status("navigation") as status:
        res = navbench.run(pairs, seed, lambda what: status.update(f"navigation: {what}"))
    _save(save, res)
    if as_json:
        typer.echo(json.dumps(res, indent=2, default=float))
        return
    from rich.console import Console
    from rich.table import Table

    t = Table(title=f"Navigation, planning radius {res['planning_radius_m']:.2f} m")
    for col in (
        "map",
        "nodes",
        "edges",
        "grid cells",
        "pairs",
        "length / grid",
        "plan ms",
        "grid A* ms",
        "speed-up",
        "compiled 5 cm ms",
        "speed-up",
        "compiled native ms",
        "speed-up",
        "min clearance",
    ):
        t.add_column(col, justify="right")
    for name, m in res["maps"].items():
        t.add_row(
            name,
            str(m["nodes"]),
            str(m["edges"]),
            str(m["inflated_grid_free_cells"]),
            f"{m['pairs']} ({m['planner_failures']} failed)",
            f"{m['path_length_ratio_median']:.3f}",
            f"{m['planning_ms_median']:.1f}",
            f"{m['grid_astar_ms_median']:.0f}",
            f"{m['planning_speedup_median']:.0f} x",
            f"{m['grid_mcp_ms_median']:.1f}",
            f"{m['speedup_vs_compiled_median']:.1f} x",
            "-" if m["native_mcp_ms_median"] is None else f"{m['native_mcp_ms_median']:.1f}",
            "-"
            if m["speedup_vs_native_compiled_median"] is None
            else f"{m['speedup_vs_native_compiled_median']:.2f} x",
            f"{m['min_clearance_to_walls_m']:.3f} m",
        )
    Console().print(t)
    _emit(
        res,
        False,
        "targets",
        [
            ("grid free cells / nodes (worst map)", f"{res['node_ratio']:.0f}"),
            ("path length / grid path (median)", f"{res['path_length_ratio_median']:.3f}"),
            ("planning speed-up (median)", f"{res['planning_speedup_median']:.0f} x"),
            (
                "... against the compiled grid planner (median)",
                f"{res['speedup_vs_compiled_median']:.1f} x",
            ),
            (
                "graph update p50 / p95",
                f"{res['update_p50_ms']:.1f} / {res['update_p95_ms']:.1f} ms",
            ),
            ("paths closer than r to a wall", str(res["clearance_violations"])),
        ],
    )


@bench_app.command("explore")
def bench_explore(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    worlds: str = typer.Option(
        "data:loop,data:cross,data:maze,data:zigzag,office,rooms",
        help="Worlds, comma separated (data:NAME, procedural names or .yaml paths).",
    ),
    robots: str = typer.Option("1,3", help="Robot counts, comma separated."),
    seeds: int = typer.Option(5, min=1, help="Seeds per world and robot count."),
    first_seed: int = typer.Option(
        0, min=0, help="First seed (runs seeds FIRST_SEED .. FIRST_SEED + SEEDS - 1)."
    ),
    profile: str = typer.Option(
        "thesis",
        help="Robot profiles, comma separated (thesis, turtlebot3, turtlebot4, hokuyo, "
        "thesis-noisy-odometry).",
    ),
    nearest: bool = typer.Option(
        True, help="Also run the nearest-frontier baseline (3 robots, maze and loop)."
    ),
    speed: float = typer.Option(
        0.0, help="Simulated seconds per wall second, at most (0: as fast as possible)."
    ),
    wall_limit: float = typer.Option(1800.0, help="Wall-clock seconds per exploration."),
    load_robots: int = typer.Option(10, help="Robots of the coordinator load test (0: skip)."),
    load_time: float = typer.Option(60.0, help="Simulated seconds of the load test."),
    out: Path = typer.Option(None, help="Folder of the runs (default: a temporary folder)."),
    unknown_start: bool = typer.Option(
        False,
        "--unknown-start",
        help="Instead: each run twice from the same scattered random starts, told and not "
        "told (launch --unknown-start); frames found, wrong merges, t99 ratio.",
    ),
    wrong_anchor: str = typer.Option(
        "",
        help="With --unknown-start, a fault injection in the runs not told: ROBOT's first "
        "frame sent DX m, DY m and DEG degrees off (ROBOT:DX,DY,DEG); merges undone counted.",
    ),
    config: Path = typer.Option(
        None, "--config", "-c", help="TOML config the runs start from (profiles apply on it)."
    ),
    start_error: str = typer.Option(
        "",
        help="In the runs with the starts told, tell ROBOT's start DX metres, DY metres and "
        "DEG degrees off where it stands (ROBOT:DX,DY,DEG): a start measured badly.",
    ),
) -> None:
    """Whole explorations (t99, success, IoU) against the idealised reference run for the
    same world, robots and profile, and the coordinator cycle under load.

    The full default matrix takes many hours on 2 cores; pass --worlds/--seeds/--robots
    for a subset. The reference's runs are cached in runs/reference-cache/."""
    from rich.console import Console

    from agents.anchoring import robot_offset, wrong_anchor_fault
    from polyswarm.benchmarks import explore as eb
    from polyswarm.config import Config, load_config, with_profile

    base = load_config(config) if config else Config()
    names = _names(profile)
    for name in names:
        with_profile(base, name)  # an unknown profile fails here, before any run
    wrong_anchor_fault(wrong_anchor)  # and a bad fault
    robot_offset(start_error, "start error")
    console = Console(stderr=True)
    with console.status("explorations") as status:

        def on_run(k, n, spec, row) -> None:
            what = (
                f"{spec.world}, {spec.profile}, {spec.robots} robot(s), {spec.strategy}, "
                f"seed {spec.seed}"
            )
            if row is None:
                status.update(f"run {k + 1}/{n}: {what}")
            else:
                t99 = "never" if row["t99_s"] is None else f"{row['t99_s']:.1f} s"
                console.log(
                    f"{what}: t99 {t99} (reference {row['reference_t99_s']} s), coverage "
                    f"{row['final_coverage']:.3f}, wall {row['wall_time_s']:.0f} s"
                )

        res = eb.run(
            list(_names(worlds)),
            [int(r) for r in robots.split(",") if r],
            seeds,
            nearest,
            speed,
            wall_limit,
            out,
            load_robots,
            load_time,
            on_run,
            first_seed,
            names,
            unknown_start,
            wrong_anchor,
            base,
            start_error,
        )
    _save(save, res)
    if as_json:
        typer.echo(json.dumps(res, indent=2, default=float))
        return
    from rich.table import Table

    if unknown_start:
        _unknown_table(res["unknown_start"], seeds)
        return

    t = Table(title=f"Exploration, t99 over {seeds} seed(s) (simulated s)")
    for col in ("profile", "world", "robots", "t99 median", "reference", "ratio", "worst ratio"):
        t.add_column(col, justify="right")
    t.add_column("success", justify="right")

    def num(v, fmt: str) -> str:
        return "-" if v is None else format(v, fmt)

    for prof, ws in res["profiles"].items():
        for w, by_n in ws.items():
            for n, d in by_n.items():
                t.add_row(
                    prof,
                    w,
                    n,
                    num(d["t99_median_s"], ".0f"),
                    num(d["reference_t99_s"], ".0f"),
                    num(d["t99_ratio_vs_reference"], ".2f"),
                    num(d["t99_ratio_vs_reference_worst"], ".2f"),
                    f"{d['success_rate']:.2f}",
                )
    Console().print(t)
    rows = [
        ("success rate (99 %, no collision, no crash, IoU)", f"{res['success_rate']:.2f}"),
        ("map IoU, worst run", num(res["map_iou_min"], ".3f")),
        ("reachable area unexplored, worst run", num(res["unexplored_reachable_m2_max"], ".1f")),
        ("wall collisions (all runs)", str(res["wall_collisions"])),
        ("runs with a crashed process", str(res["crashed_runs"])),
    ]
    rows += [(f"t99 3 vs 1 robot, {w}", f"{v:.2f}") for w, v in res["t99_ratio_3_vs_1"].items()]
    rows += [
        (f"t99 hungarian vs nearest, {w}", f"{v:.2f}")
        for w, v in res["t99_ratio_vs_nearest"].items()
    ]
    if "coordinator_load" in res:
        ld = res["coordinator_load"]
        rows.append(
            (
                f"coordinator cycle, {ld['robots']} robots, p50 / p95",
                f"{ld['cycle_p50_ms']:.0f} / {ld['cycle_p95_ms']:.0f} ms",
            )
        )
    _emit(res, False, "exploration summary", rows)


@bench_app.command("bandwidth")
def bench_bandwidth(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    logs: bool = typer.Option(True, help="Measure every log of ../shared/data/logs."),
    bags: bool = typer.Option(
        True, help="Measure the real recordings of ../shared/data/bags (their own odometry)."
    ),
    sim_world: str = typer.Option("office", help="World of the simulated exploration."),
    sim_robots: int = typer.Option(3, min=0, help="Robots of the simulated run (0: skip)."),
    sim_time: float = typer.Option(300.0, help="Simulated seconds of the exploration."),
    seed: int = typer.Option(0, help="Seed of the odometry and sensor noise."),
    out: Path = typer.Option(Path("runs/bandwidth"), help="Folder for CSV files and plots."),
) -> None:
    """PolyMap deltas against occupancy-grid sharing on the same scans and poses."""
    from rich.console import Console
    from rich.progress import Progress

    from polyswarm.benchmarks import bandwidth as bw
    from polyswarm.config import Config
    from polyswarm.data import shared_data_dir

    cfg = Config()
    results = []
    console = Console(stderr=True)
    with Progress(console=console, transient=True) as progress:
        recordings = []
        if logs:
            for path in sorted((shared_data_dir() / "logs").glob("*.log*")):
                task = progress.add_task(f"PolySLAM {path.name}", total=None)
                recordings.append(bw.record_log(path, cfg, seed))
                progress.remove_task(task)
        if bags:
            for name in bw.REAL_BAGS:
                task = progress.add_task(f"PolySLAM {name}", total=None)
                recordings.append(bw.record_bag(shared_data_dir() / "bags" / f"{name}.bag", cfg))
                progress.remove_task(task)
        if sim_robots > 0:
            task = progress.add_task(f"exploring {sim_world} with {sim_robots}", total=None)
            recordings.append(bw.record_simulation(sim_world, sim_robots, sim_time, seed, cfg))
            progress.remove_task(task)
        for rec in recordings:
            task = progress.add_task(f"grid baseline {rec.name}", total=len(rec.keyframes))
            res = bw.measure(rec, lambda k, n, task=task: progress.update(task, completed=k))
            progress.remove_task(task)
            bw.write_outputs(res, out)
            results.append(res)
    summary = bw.summary(results)
    summary["out"] = str(out)
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float))
    _save(save, summary)
    if as_json:
        typer.echo(json.dumps(summary, indent=2, default=float))
        return
    from rich.table import Table

    t = Table(title="Bytes sent for the same map updates (cumulative)")
    t.add_column("run")
    for s in bw.SCHEMES:
        t.add_column(s.replace("_", " "), justify="right")
    t.add_column("PolyMap / best baseline", justify="right")
    t.add_column("PolyMap / best grid delta", justify="right")
    t.add_column("map / PNG", justify="right")
    for r in results:
        c = r["cumulative_bytes"]
        t.add_row(
            r["name"],
            *[bw.fmt_bytes(c[s]) for s in bw.SCHEMES],
            f"{r['delta_bytes_ratio_vs_best_baseline']:.3f} ({r['best_baseline']})",
            f"{r['delta_bytes_ratio_vs_best_grid']:.3f}",
            f"{r['map_bytes_ratio_vs_png']:.2f}",
        )
    Console().print(t)
    for r in results:
        if r["merges_sent"]:
            console.print(
                f"{r['name']}: {r['merges_sent']} of {r['keyframes']} updates sent as merges, "
                f"{r['merges_sent'] - r['merges_not_replayed']} replayed bit for bit by the "
                f"receiver (median {r['replay_ms_median']:.1f} ms, "
                f"p95 {r['replay_ms_p95']:.1f} ms); "
                f"receiver's copy identical at the end: {r['receiver_copies_identical']}"
            )
    console.print(f"CSV files and plots in {out}")


@bench_app.command("cells")
def bench_cells(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    sizes: str = typer.Option("1,2,3,4", help="Cell sizes to compare, metres."),
    log: str = typer.Option("freiburg-101-corrected.log.gz", help="Log in ../shared/data/logs."),
) -> None:
    """Merge time against delta bytes for several cell sizes (PolySLAM over a log)."""
    from rich.console import Console
    from rich.table import Table

    from polyswarm.benchmarks import cells
    from polyswarm.data import shared_data_dir

    with Console(stderr=True).status("PolySLAM per cell size"):
        res = cells.run(shared_data_dir() / "logs" / log, [float(s) for s in sizes.split(",")])
    _save(save, res)
    if as_json:
        typer.echo(json.dumps(res, indent=2))
        return
    t = Table(title=f"Cell size on {res['log']}")
    for col in (
        "cell m",
        "merge p50 ms",
        "merge p95 ms",
        "delta bytes",
        "cells/delta",
        "map bytes",
    ):
        t.add_column(col, justify="right")
    for m in res["sizes"].values():
        t.add_row(
            f"{m['cell_size_m']:g}",
            f"{m['merge_p50_ms']:.1f}",
            f"{m['merge_p95_ms']:.1f}",
            f"{m['delta_bytes']:,}",
            f"{m['cells_per_delta_mean']:.1f}",
            f"{m['map_bytes']:,}",
        )
    Console().print(t)


def _fault_row(r: dict) -> tuple[str, str]:
    at = f"{r['kill_at_sim_s']:.0f} s simulated"
    what = f"{r['world']} seed {r['seed']}: {r['victim']} killed at {at}"
    if not r["killed"]:
        return what, "not killed (the run ended first)"
    t99 = "never" if r["t99_s"] is None else f"{r['t99_s']:.0f} s"
    restarts = ", ".join(f"{k} x{n}" for k, n in r["restarts"].items()) or "none"
    return what, f"t99 {t99}, lost {100 * r['lost_share_max']:.2f} %, restarts {restarts}"


@bench_app.command("faults")
def bench_faults(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    worlds: str = typer.Option("office,data:maze", help="Worlds, comma separated."),
    seeds: int = typer.Option(5, min=1, help="Seeds per world (each draws victim and moment)."),
    robots: int = typer.Option(3, min=1, help="Robots per run."),
    wall_limit: float = typer.Option(1500.0, help="Wall-clock seconds per run, at most."),
    out: Path = typer.Option(Path("runs/bench-faults"), help="Folder of the runs."),
) -> None:
    """SIGKILL of one process (agent, simulator or coordinator) from outside at a random
    moment of each run: does the exploration still reach 99 %, and is anything a robot
    shared missing from the merged map?"""
    from rich.console import Console

    from polyswarm.benchmarks import faults

    with Console(stderr=True).status("faults") as status:
        res = faults.run(
            _names(worlds),
            seeds,
            robots,
            wall_limit,
            out,
            lambda what: status.update(f"faults: {what}"),
        )
    _save(save, res)
    rows = [_fault_row(r) for r in res["runs"]]
    ok = f"{res['runs_ok']} of {res['runs_total']}"
    rows.append(("runs reaching 99 % with nothing lost", ok))
    _emit(res, as_json, f"Faults: {robots} robots, one process killed per run", rows)


@bench_app.command("load")
def bench_load(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    robots: int = typer.Option(10, min=1, help="Robots (agent processes)."),
    world: str = typer.Option("data:maze", help="World to explore."),
    duration: float = typer.Option(1800.0, help="Soak length, wall-clock seconds."),
    out: Path = typer.Option(None, help="Run folder (default: a temporary folder)."),
    robots_nice: int = typer.Option(
        5,
        min=0,
        max=19,
        help="Niceness of the simulator and agents (they stand for the robots' own "
        "computers; 0: the coordinator competes with them for the processor).",
    ),
) -> None:
    """Many robots against one coordinator: lost messages, cycle p95, memory growth."""
    from rich.console import Console

    from polyswarm.benchmarks import load

    with Console(stderr=True).status(f"{robots} robots for {duration:.0f} s"):
        res = load.run(robots, world, duration, out, robots_nice=robots_nice)
    _save(save, res)
    if as_json:
        typer.echo(json.dumps(res, indent=2, default=float))
        return
    g, g2 = res["memory_growth_fraction"], res["memory_growth_fraction_second_half"]
    ga = res["agent_memory_growth_second_half_max"]
    kb, kb_max = res["agent_kb_per_keyframe_median"], res["agent_kb_per_keyframe_max"]
    _emit(
        res,
        False,
        f"Load: {res['robots']} robots on {res['world']}",
        [
            ("wall / simulated time", f"{res['wall_time_s']:.0f} s / {res['sim_time_s']:.0f} s"),
            ("messages lost at the end (map versions)", str(res["messages_lost"])),
            (
                "... in transit: gaps, map fetches (bytes)",
                f"{res['robot_map_gaps']}, {res['robot_map_fetches']} "
                f"({res['robot_map_fetch_bytes']:,} B)",
            ),
            ("coordinator cycle p95", f"{res['coordinator_cycle_p95_ms']:.0f} ms"),
            ("... its processor time p95", f"{res['coordinator_cycle_cpu_p95_ms']:.0f} ms"),
            ("coordinator memory growth", "-" if g is None else f"{100 * g:.1f} %"),
            ("... over the second half", "-" if g2 is None else f"{100 * g2:.1f} %"),
            ("agents' memory growth over the second half, worst", _pct(ga)),
            ("agents' memory per keyframe, median / worst", f"{_kb(kb)} / {_kb(kb_max)}"),
            ("crashed processes", ", ".join(res["crashed_processes"]) or "none"),
        ],
    )


def _pct(fraction: float | None) -> str:
    return "-" if fraction is None else f"{100 * fraction:.1f} %"


def _kb(kb: float | None) -> str:
    return "-" if kb is None else f"{kb:.1f} kB"


@app.command("fuzz")
def fuzz_cmd(
    count: int = typer.Option(100_000, min=1, help="Mutated inputs per decoder."),
    seed: int = typer.Option(0, help="Seed of the mutations."),
    as_json: bool = JSON_OPT,
) -> None:
    """Fuzz every decoder of outside bytes (messages, maps, deltas, ROS CDR)."""
    from rich.console import Console

    from polyswarm.benchmarks import fuzz
    from polyswarm.errors import PolyswarmError

    with Console(stderr=True).status("fuzzing") as status:
        res = fuzz.run(count, seed, lambda n, k, c: status.update(f"fuzzing {n}: {k}/{c}"))
    if as_json:
        typer.echo(json.dumps(res, indent=2))
    else:
        _emit(
            res,
            False,
            f"Fuzzing, {count:,} inputs per decoder",
            [
                (n, f"{r['rejected']:,} rejected, {r['accepted']:,} ok, {r['crashes']} crashes")
                for n, r in res.items()
            ],
        )
    crashed = {n: r["examples"] for n, r in res.items() if r["crashes"]}
    if crashed:
        raise PolyswarmError(f"decoders crashed: {crashed}")


@bench_app.command("merge")
def bench_merge(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    worlds: str = typer.Option("office,rooms,loop,cross,maze", help="Worlds, comma separated."),
    seeds: int = typer.Option(5, min=1, help="Seeds per world (starts, headings, noise)."),
    robots: int = typer.Option(3, min=2, help="Robots per run."),
    profile: str = typer.Option("thesis", help="Robot profiles, comma separated."),
    jobs: int = typer.Option(1, min=1, help="Runs side by side (worker processes)."),
) -> None:
    """Maps of robots with unknown starts: polyswarm's map matching against the peer
    method (multirobot_map_merge's feature-based grid merging) at the same moments."""
    from rich.console import Console

    from polyswarm.benchmarks import merge

    with Console(stderr=True).status("merge") as status:
        res = merge.run(
            _names(worlds),
            seeds,
            robots,
            _names(profile),
            lambda what: status.update(f"merge: {what}"),
            jobs,
        )
    _save(save, res)
    if as_json:
        typer.echo(json.dumps(res, indent=2, default=float))
        return
    from rich.table import Table

    t = Table(
        title=f"Unknown starts: robot k's map against robot 1's, every {res['snapshot_s']:.0f} s"
    )
    cols = ("method", "accepted", "correct", "wrong", "err p50 m", "err max m", "merged")
    for col in (*cols, "delay p50 s", "final err max m"):
        t.add_column(col, justify="left" if col == "method" else "right", no_wrap=True)
    for name, m in res["methods"].items():
        t.add_row(
            name,
            str(m["accepted"]),
            str(m["correct"]),
            str(m["wrong"]),
            "-" if m["err_m_median"] is None else f"{m['err_m_median']:.3f}",
            "-" if m["err_m_max"] is None else f"{m['err_m_max']:.2f}",
            f"{m['pairs_merged_correctly']} of {m['pairs_overlapping']}",
            "-" if m["delay_s_median"] is None else f"{m['delay_s_median']:.0f}",
            "-" if m["final_err_m_max"] is None else f"{m['final_err_m_max']:.3f}",
        )
    Console().print(t)


def _unknown_table(res: dict, seeds: int) -> None:
    from rich.console import Console
    from rich.table import Table

    t = Table(title=f"Unknown starts against the same starts told, {seeds} seed(s)")
    cols = ("profile", "world", "robots", "success", "all anchored", "wrong merges left")
    more = ("wrong sent, undone", "frame err max", "pose err p95 max", "t99 ratio median", "worst")
    for col in (*cols, *more):
        t.add_column(col, justify="right")
    for prof, ws in res.items():
        for w, by_n in ws.items():
            for n, d in by_n.items():
                err = d["frame_err_m_max"]
                t.add_row(
                    prof,
                    w,
                    n,
                    f"{d['success_rate']:.2f}",
                    "yes" if d["all_anchored"] else "no",
                    str(d["wrong_merges"]),
                    f"{d['wrong_frames_sent']}, {d['merges_undone']}",
                    "-" if err is None else f"{err:.3f} m, {d['frame_err_deg_max']:.2f} deg",
                    "-" if d["pose_err_m_p95_max"] is None else f"{d['pose_err_m_p95_max']:.3f} m",
                    "-" if d["t99_ratio_median"] is None else f"{d['t99_ratio_median']:.2f}",
                    "-" if d["t99_ratio_worst"] is None else f"{d['t99_ratio_worst']:.2f}",
                )
    Console().print(t)


@bench_app.command("cycle")
def bench_cycle(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    worlds: str = typer.Option(
        "office,rooms,furnished,data:nav2-depot,data:loop,data:cross,data:zigzag,data:maze",
        help="Worlds, comma separated.",
    ),
    robots: int = typer.Option(3, min=1, help="Robots per run."),
    sim_time: float = typer.Option(
        600.0, min=1.0, help="Simulated seconds at most (a run ends with its mission)."
    ),
    seed: int = typer.Option(0, help="Seed of the worlds and the simulation."),
    replay_workers: int = typer.Option(
        1, min=0, help="Processes replaying robots' merges (0: on the coordinator's thread)."
    ),
    merge_process: bool = typer.Option(
        True, help="Merge and update the graph on a process of its own (else on the thread)."
    ),
) -> None:
    """The coordinator's cycle per world, all its work included (replays, merge, plan)."""
    from rich.console import Console
    from rich.table import Table

    from polyswarm.benchmarks import cycle

    with Console(stderr=True).status("cycle") as status:
        res = cycle.run(
            _names(worlds),
            robots,
            sim_time,
            seed,
            lambda what: status.update(f"cycle: {what}"),
            replay_workers,
            merge_process,
        )
    _save(save, res)
    if as_json:
        typer.echo(json.dumps(res, indent=2, default=float))
        return
    target = res["target_p95_ms"]
    goal = "" if target is None else f" (target p95: {target:.0f} ms)"
    where = "replays on its thread"
    if replay_workers:
        where = f"replays on {replay_workers} process(es)"
    where += ", merges on a process" if merge_process else ", merges on its thread"
    t = Table(title=f"Coordinator cycle, {robots} robots, {where}{goal}")
    cols = ("world", "sim s", "cycles", "p50 ms", "p95 ms", "max ms", "cpu p95 ms")
    for col in (*cols, "pool cpu s", "pool lag p95 ms", "merger cpu s", "merge lag p95 ms"):
        t.add_column(col, justify="left" if col == "world" else "right")
    for w, r in res["worlds"].items():
        t.add_row(
            w,
            f"{r['sim_time_s']:.0f}",
            str(r["cycles"]),
            f"{r['cycle_p50_ms']:.0f}",
            f"{r['cycle_p95_ms']:.0f}",
            f"{r['cycle_max_ms']:.0f}",
            f"{r['cycle_cpu_p95_ms']:.0f}",
            f"{r['replay_workers_cpu_s']:.1f}",
            "-" if r["replay_lag_p95_ms"] is None else f"{r['replay_lag_p95_ms']:.0f}",
            f"{r['merge_process_cpu_s']:.1f}",
            "-" if r["merge_lag_p95_ms"] is None else f"{r['merge_lag_p95_ms']:.0f}",
        )
    Console().print(t)


@bench_app.command("memory")
def bench_memory(as_json: bool = JSON_OPT, save: str | None = SAVE_OPT) -> None:
    """What a robot's SLAM keeps per keyframe (Python heap), on the shared logs."""
    from rich.console import Console

    from polyswarm.benchmarks import memory

    with Console(stderr=True).status("memory") as status:
        res = memory.run(lambda name: status.update(f"memory: {name}"))
    _save(save, res)
    rows = []
    for name, r in res["logs"].items():
        half = r["kb_per_keyframe_second_half"]
        rows.append(
            (
                f"{name} ({r['keyframes']} keyframes, {r['odometry']} odometry)",
                "-"
                if half is None
                else f"{half:.1f} kB per keyframe, second half; heap {r['heap_mb_last']:.1f} MB",
            )
        )
    _emit(res, as_json, "SLAM memory per keyframe (Python heap)", rows)
