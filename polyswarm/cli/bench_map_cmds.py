"""Benchmarks of maps and their cost: SLAM, navigation, bandwidth, cells, merging,
memory."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from polyswarm.cli import bench_app
from polyswarm.cli.bench_cmds import JSON_OPT, SAVE_OPT, _emit, _names, _save


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


def _bandwidth_table(results: list[dict]):
    """Cumulative bytes of every scheme per run, and PolyMap's ratios."""
    from rich.table import Table

    from polyswarm.benchmarks import bandwidth as bw

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
    return t


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
    Console().print(_bandwidth_table(results))
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
