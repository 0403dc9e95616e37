"""``polyswarm bench NAME [--json]``: benchmarks with a table or machine-readable output."""

from __future__ import annotations

import json

import typer

from polyswarm.cli import bench_app

JSON_OPT = typer.Option(False, "--json", help="Print JSON instead of a table.")


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
    cell_size: float = typer.Option(2.0, help="Cell size, metres."),
) -> None:
    """PolyMap bytes against PNG/zlib of the same 5 cm grid; merge latency."""
    from rich.console import Console
    from rich.table import Table

    from polyswarm.benchmarks import format as fmt

    console = Console(stderr=True)
    with console.status("converting worlds and merging keyframes"):
        res = fmt.run(cell_size)
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
    world: str = typer.Option("data:maze", help="World to step (default: the largest)."),
) -> None:
    """Lidar scans per second, real-time factor against ray casting alone, memory."""
    from rich.console import Console

    from polyswarm.benchmarks import sim as simbench

    with Console(stderr=True).status(f"stepping {world}"):
        res = simbench.run(world)
    rows = [(f"scans/s, {n} robot(s)", f"{v:.0f}") for n, v in res["scans_per_s"].items()]
    rows += [
        ("real-time factor, 3 robots", f"{res['real_time_factor_3_robots']:.1f}"),
        ("ray casting only bound", f"{res['raycast_only_real_time_factor_3_robots']:.1f}"),
        ("share of step not ray casting", f"{100 * res['non_raycast_fraction_3_robots']:.0f} %"),
        ("peak memory", f"{res['peak_memory_mb']:.0f} MB"),
    ]
    _emit(res, as_json, f"simulator on {res['world']} ({res['beams']} beams)", rows)


@bench_app.command("slam")
def bench_slam(
    as_json: bool = JSON_OPT,
    worlds: str = typer.Option("loop,cross,zigzag,maze", help="Thesis worlds to drive through."),
) -> None:
    """PolySLAM on the thesis' worlds and the real logs; refinement; speed (minutes)."""
    from rich.console import Console

    from polyswarm.benchmarks import slam as slambench

    console = Console(stderr=True)
    with console.status("PolySLAM") as status:
        res = slambench.run(
            lambda what: status.update(f"PolySLAM: {what}"), tuple(worlds.split(","))
        )
    if as_json:
        typer.echo(json.dumps(res, indent=2, default=float))
        return
    rows = []
    for w, m in res["worlds"].items():
        ours, thesis = 100 * m["max_trans_error_ratio"], 100 * m["thesis_max_trans_error_ratio"]
        rows.append((f"{w}: max error / distance (thesis)", f"{ours:.3f} % ({thesis:.3f} %)"))
        rows.append((f"{w}: map IoU, polygons", f"{m['map_iou']:.3f}, {m['polygons']}"))
    for name, m in res["logs"].items():
        rows.append(
            (
                f"log {name}: ATE (odometry)",
                f"{m['ate_rmse_m']:.3f} m ({m['odometry_ate_rmse_m']:.3f} m)",
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
    rows.append(("real-time factor (worst world)", f"{res['realtime_factor_min']:.1f} x"))
    _emit(res, False, "PolySLAM", rows)


@bench_app.command("nav")
def bench_nav(
    as_json: bool = JSON_OPT,
    pairs: int = typer.Option(50, min=1, help="Random start/goal pairs per map."),
    seed: int = typer.Option(0, help="Seed of the start/goal draw and the PolySLAM run."),
) -> None:
    """Navigation graph and planner against 8-connected A* on the inflated 5 cm grid."""
    from rich.console import Console

    from polyswarm.benchmarks import nav as navbench

    with Console(stderr=True).status("navigation") as status:
        res = navbench.run(pairs, seed, lambda what: status.update(f"navigation: {what}"))
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
                "graph update p50 / p95",
                f"{res['update_p50_ms']:.1f} / {res['update_p95_ms']:.1f} ms",
            ),
            ("paths closer than r to a wall", str(res["clearance_violations"])),
        ],
    )
