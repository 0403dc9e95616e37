"""Benchmarks of whole missions: exploration against the reference, faults, a
long soak, the coordinator's cycle."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from polyswarm.cli import app, bench_app
from polyswarm.cli.bench_cmds import JSON_OPT, SAVE_OPT, _emit, _names, _save


def _explore_progress(console, status):
    """The callback that shows each exploration run starting and its result."""

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

    return on_run


def _num(v, fmt: str) -> str:
    return "-" if v is None else format(v, fmt)


def _explore_table(res: dict, seeds: int):
    """t99 against the reference per profile, world and robot count."""
    from rich.table import Table

    t = Table(title=f"Exploration, t99 over {seeds} seed(s) (simulated s)")
    for col in ("profile", "world", "robots", "t99 median", "reference", "ratio", "worst ratio"):
        t.add_column(col, justify="right")
    t.add_column("success", justify="right")
    for prof, ws in res["profiles"].items():
        for w, by_n in ws.items():
            for n, d in by_n.items():
                t.add_row(
                    prof,
                    w,
                    n,
                    _num(d["t99_median_s"], ".0f"),
                    _num(d["reference_t99_s"], ".0f"),
                    _num(d["t99_ratio_vs_reference"], ".2f"),
                    _num(d["t99_ratio_vs_reference_worst"], ".2f"),
                    f"{d['success_rate']:.2f}",
                )
    return t


def _explore_rows(res: dict) -> list[tuple[str, str]]:
    """The exploration summary: success, IoU, collisions, ratios, coordinator load."""
    rows = [
        ("success rate (99 %, no collision, no crash, IoU)", f"{res['success_rate']:.2f}"),
        ("map IoU, worst run", _num(res["map_iou_min"], ".3f")),
        ("reachable area unexplored, worst run", _num(res["unexplored_reachable_m2_max"], ".1f")),
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
    return rows


EXPLORE_WORLDS_OPT = typer.Option(
    "data:loop,data:cross,data:maze,data:zigzag,office,rooms",
    help="Worlds, comma separated (data:NAME, procedural names or .yaml paths).",
)

EXPLORE_PROFILE_OPT = typer.Option(
    "thesis",
    help="Robot profiles, comma separated (thesis, turtlebot3, turtlebot4, hokuyo, "
    "thesis-noisy-odometry).",
)

EXPLORE_UNKNOWN_START_OPT = typer.Option(
    False,
    "--unknown-start",
    help="Instead: each run twice from the same scattered random starts, told and not "
    "told (launch --unknown-start); frames found, wrong merges, t99 ratio.",
)

EXPLORE_WRONG_ANCHOR_OPT = typer.Option(
    "",
    help="With --unknown-start, a fault injection in the runs not told: ROBOT's first "
    "frame sent DX m, DY m and DEG degrees off (ROBOT:DX,DY,DEG); merges undone counted.",
)

EXPLORE_CONFIG_OPT = typer.Option(
    None, "--config", "-c", help="TOML config the runs start from (profiles apply on it)."
)

EXPLORE_START_ERROR_OPT = typer.Option(
    "",
    help="In the runs with the starts told, tell ROBOT's start DX metres, DY metres and "
    "DEG degrees off where it stands (ROBOT:DX,DY,DEG): a start measured badly.",
)


@bench_app.command("explore")
def bench_explore(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    worlds: str = EXPLORE_WORLDS_OPT,
    robots: str = typer.Option("1,3", help="Robot counts, comma separated."),
    seeds: int = typer.Option(5, min=1, help="Seeds per world and robot count."),
    first_seed: int = typer.Option(
        0, min=0, help="First seed (runs seeds FIRST_SEED .. FIRST_SEED + SEEDS - 1)."
    ),
    profile: str = EXPLORE_PROFILE_OPT,
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
    unknown_start: bool = EXPLORE_UNKNOWN_START_OPT,
    wrong_anchor: str = EXPLORE_WRONG_ANCHOR_OPT,
    config: Path = EXPLORE_CONFIG_OPT,
    start_error: str = EXPLORE_START_ERROR_OPT,
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
        on_run = _explore_progress(console, status)

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

    if unknown_start:
        _unknown_table(res["unknown_start"], seeds)
        return

    Console().print(_explore_table(res, seeds))
    _emit(res, False, "exploration summary", _explore_rows(res))


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
    duration: float = typer.Option(1800.0, "--wall-limit", help="Soak length, wall-clock seconds."),
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


def _fault_row(r: dict) -> tuple[str, str]:
    at = f"{r['kill_at_sim_s']:.0f} s simulated"
    what = f"{r['world']} seed {r['seed']}: {r['victim']} killed at {at}"
    if not r["killed"]:
        return what, "not killed (the run ended first)"
    t99 = "never" if r["t99_s"] is None else f"{r['t99_s']:.0f} s"
    restarts = ", ".join(f"{k} x{n}" for k, n in r["restarts"].items()) or "none"
    return what, f"t99 {t99}, lost {100 * r['lost_share_max']:.2f} %, restarts {restarts}"


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
