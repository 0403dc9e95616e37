"""``polyswarm bench fleet``: robots on hosts of their own against one network stack."""

from __future__ import annotations

from pathlib import Path

import typer

from polyswarm.cli import bench_app
from polyswarm.cli.bench_cmds import JSON_OPT, SAVE_OPT, _emit, _save


@bench_app.command("fleet")
def bench_fleet(
    as_json: bool = JSON_OPT,
    save: str | None = SAVE_OPT,
    robots: str = typer.Option("10,25", help="Robot counts, comma separated."),
    world: str = typer.Option("data:nav2-warehouse", help="World to explore."),
    wall_limit: float = typer.Option(300.0, help="Wall-clock seconds per run."),
    out: Path | None = typer.Option(None, help="Folder of the runs (default: a temporary one)."),
) -> None:
    """Coordinator cycle and bytes per robot, one network stack against --netns (root)."""
    from rich.console import Console

    from polyswarm.benchmarks import fleet
    from polyswarm.errors import ConfigError
    from polyswarm.runners.netns import check_can_build

    check_can_build()
    try:
        counts = tuple(int(n) for n in robots.split(",") if n.strip())
    except ValueError:
        raise ConfigError(f"--robots {robots!r}: expected counts such as 10,25") from None
    console = Console(stderr=True)

    def on_run(n: int, netns: bool) -> None:
        where = "in namespaces" if netns else "on one stack"
        console.print(f"{n} robots {where}, {wall_limit:.0f} s")

    res = fleet.run(counts, world, wall_limit, out, on_run=on_run)
    _save(save, res)
    rows = []
    for r in res["runs"]:
        where = "netns" if r["netns"] else "loopback"
        rows.append(
            (
                f"{r['robots']} robots, {where}: cycle p95 / bytes per robot per sim s",
                f"{r['coordinator_cycle_p95_ms']:.0f} ms / {r['bytes_per_robot_per_sim_s']:.0f} B"
                f" (coverage {100 * r['final_coverage']:.0f} %)",
            )
        )
    for n, ratio in res["bytes_per_robot_ratio_netns_vs_loopback"].items():
        rows.append((f"{n} robots: bytes per robot, netns / loopback", f"{ratio:.2f}"))
    _emit(res, as_json, f"Fleet on {world}", rows)
