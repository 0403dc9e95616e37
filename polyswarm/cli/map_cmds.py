"""``polyswarm map convert|info|export``."""

from __future__ import annotations

from pathlib import Path

import typer

from polyswarm.cli import map_app
from polyswarm.errors import PolyswarmError


def _load_grid(source: Path, resolution: float | None):
    from polyswarm.io.mapserver import read_map

    grid = read_map(source)
    if resolution is not None and abs(resolution - grid.resolution) > 1e-9:
        factor = grid.resolution / resolution
        if abs(factor - round(factor)) > 1e-6 or round(factor) < 1:
            raise PolyswarmError(
                f"--resolution {resolution} m must divide the map's {grid.resolution} m"
            )
        grid = grid.upsample(round(factor))
    return grid


@map_app.command("convert")
def convert(
    source: Path = typer.Argument(..., help="ROS map_server YAML (PGM/PNG + YAML)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output .polymap file."),
    cell_size: float = typer.Option(2.0, help="Cell size of the GridPolyMap, metres."),
    resolution: float | None = typer.Option(
        None, help="Resample the grid to this resolution first (metres per cell)."
    ),
    diagonal_tolerance: float = typer.Option(
        0.25, help="Staircases within this many grid cells of a line become diagonals (0: off)."
    ),
) -> None:
    """Convert an occupancy grid map to a PolyMap (thesis Algorithm 1, plus diagonals)."""
    from rich.console import Console

    from polyswarm.grids.convert import grid_to_polymap
    from protocols.files import write_polymap

    grid = _load_grid(source, resolution)
    with Console(stderr=True).status(
        f"converting {source.name} ({grid.shape[1]}x{grid.shape[0]} cells)"
    ):
        pmap = grid_to_polymap(grid, cell_size, diagonal_tolerance)
        nbytes = write_polymap(pmap, out)
    typer.echo(f"wrote {out} ({nbytes} bytes, {sum(pmap.vector_counts().values())} vectors)")


@map_app.command("info")
def info(path: Path = typer.Argument(..., help="A .polymap file.")) -> None:
    """Polygons, vectors by type, encoded bytes and explored area of a map."""
    from rich.console import Console
    from rich.table import Table

    from protocols.files import read_polymap

    pmap = read_polymap(path)
    counts = pmap.vector_counts()
    dissolved = pmap.dissolve()
    table = Table(title=str(path), show_header=False)
    table.add_row("cells", f"{len(pmap.cells)} of {pmap.cell_size:g} m")
    table.add_row("polygons (whole map)", str(len(dissolved)))
    table.add_row("polygons (in cells)", str(pmap.polygon_count()))
    for k, v in counts.items():
        table.add_row(f"{k} vectors", str(v))
    table.add_row("encoded bytes", str(path.stat().st_size))
    table.add_row("explored area", f"{pmap.explored_area():.2f} m2")
    table.add_row("map version", str(pmap.version))
    Console().print(table)


@map_app.command("export")
def export(
    path: Path = typer.Argument(..., help="A .polymap file."),
    out: Path = typer.Option(..., "-o", "--out", help="Output: .svg, .png, .geojson or .yaml"),
    grid: bool = typer.Option(False, "--grid", help="Draw the cell grid (svg, png)."),
    sectors: bool = typer.Option(False, "--sectors", help="Draw sector vectors (svg, png)."),
    resolution: float = typer.Option(
        0.05, min=0.001, help="Grid resolution for .yaml, metres per cell."
    ),
    wall_thickness: float = typer.Option(
        0.1, min=0.0, help="Wall thickness assumed behind obstacle vectors for .yaml, metres."
    ),
) -> None:
    """Export a map; the format follows the suffix of --out."""
    from polyswarm.io.export import export_map
    from protocols.files import read_polymap

    pmap = read_polymap(path)
    export_map(
        pmap,
        out,
        show_grid=grid,
        show_sectors=sectors,
        grid_resolution_m=resolution,
        wall_thickness_m=wall_thickness,
    )
    typer.echo(f"wrote {out}")
