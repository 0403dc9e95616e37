"""``polyswarm bench fleet``: robots and coordinators on hosts of their own (root)."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path

import typer

from polyswarm.cli import bench_app
from polyswarm.cli.bench_cmds import JSON_OPT, SAVE_OPT, _emit, _save


class FleetPart(StrEnum):
    MESH = "mesh"  # one network stack against namespaces, 10 and 25 robots
    CUTS = "cuts"  # robots cut off for 60 s and 120 s
    TAKEOVER = "takeover"  # the active coordinator's host lost at a random moment


@bench_app.command("fleet")
def bench_fleet(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    part: FleetPart = typer.Option(
        FleetPart.MESH,
        help="mesh: cycle and bytes, one stack against --netns; cuts: robots out of range "
        "60 s and 120 s; takeover: the active coordinator's host lost.",
    ),
    robots: str = typer.Option("10,25", help="mesh: robot counts, comma separated."),
    world: str = typer.Option("data:nav2-warehouse", help="mesh: world to explore."),
    wall_limit: float = typer.Option(300.0, help="mesh: wall-clock seconds per run."),
    runs: int = typer.Option(10, min=1, help="takeover: runs (seeds 0, 1, ...)."),
    out: Path | None = typer.Option(None, help="Folder of the runs (default: a temporary one)."),
) -> None:
    """A fleet across hosts (network namespaces, needs root): mesh, link cuts, takeover."""
    from rich.console import Console

    from polyswarm.benchmarks import fleet
    from polyswarm.errors import ConfigError
    from polyswarm.runners.netns import check_can_build

    check_can_build()
    console = Console(stderr=True)
    if part == FleetPart.CUTS:
        res = fleet.cuts(out=out, on_run=lambda w, s: console.print(f"{w}, seed {s}"))
        rows = [
            (
                f"{r['world']} seed {r['seed']}: coverage, t99, keyframes while cut",
                f"{100 * r['final_coverage']:.1f} %, "
                + ("never" if r["t99_s"] is None else f"{r['t99_s']:.0f} s")
                + ", "
                + ", ".join(
                    f"{k} {'(no return seen)' if n is None else n}"
                    for k, n in r["keyframes_while_cut"].items()
                ),
            )
            for r in res["runs"]
        ]
        rows.append(
            (
                "99 % in every run / maps agree in every run",
                f"{res['reached_99_all']} / {res['maps_agree_all']}",
            )
        )
    elif part == FleetPart.TAKEOVER:
        res = fleet.takeovers(
            runs, out=out, on_run=lambda k, at: console.print(f"run {k}: lost at {at} s")
        )
        rows = [
            ("takeover p95 / max, wall s", f"{res['takeover_p95_s']} / {res['takeover_max_s']}"),
            ("took over / missions done", f"{res['took_over']} / {res['missions_done']} of {runs}"),
        ]
    else:
        try:
            counts = tuple(int(n) for n in robots.split(",") if n.strip())
        except ValueError:
            raise ConfigError(f"--robots {robots!r}: expected counts such as 10,25") from None

        def on_run(n: int, netns: bool) -> None:
            where = "in namespaces" if netns else "on one stack"
            console.print(f"{n} robots {where}, {wall_limit:.0f} s")

        res = fleet.run(counts, world, wall_limit, out, on_run=on_run)
        rows = []
        for r in res["runs"]:
            where = "netns" if r["netns"] else "loopback"
            rows.append(
                (
                    f"{r['robots']} robots, {where}: cycle p95 / bytes per robot per sim s",
                    f"{r['coordinator_cycle_p95_ms']:.0f} ms / "
                    f"{r['bytes_per_robot_per_sim_s']:.0f} B "
                    f"(coverage {100 * r['final_coverage']:.0f} %)",
                )
            )
        for n, ratio in res["bytes_per_robot_ratio_netns_vs_loopback"].items():
            rows.append((f"{n} robots: bytes per robot, netns / loopback", f"{ratio:.2f}"))
    _save(save, res)
    _emit(res, as_json, f"Fleet: {part}", rows)
