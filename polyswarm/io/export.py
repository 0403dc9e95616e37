"""Export a PolyMap by file suffix: .svg, .png, .geojson, .yaml (map_server PGM+YAML).

Colours: obstacles red, frontiers green, sectors yellow (thin), explored space light
grey; optional cell grid and robot trajectories.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from polyswarm.errors import PolyswarmError
from polyswarm.polymap import GridPolyMap, VectorType
from polyswarm.polymap.partition import partition_of

COLOURS = {
    VectorType.OBSTACLE: "#d62728",
    VectorType.FRONTIER: "#2ca02c",
    VectorType.SECTOR: "#e6c229",
}
FREE_FILL = "#eeeeee"
SUFFIXES = (".svg", ".png", ".geojson", ".yaml")


def export_map(
    pmap: GridPolyMap,
    path: str | Path,
    *,
    show_grid: bool = False,
    show_sectors: bool = False,
    trajectories: Sequence[np.ndarray] = (),
    grid_resolution_m: float = 0.05,
    wall_thickness_m: float = 0.1,
) -> Path:
    """Write ``pmap`` to ``path``; the format follows the suffix."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".svg":
        path.write_text(
            to_svg(pmap, show_grid=show_grid, show_sectors=show_sectors, trajectories=trajectories)
        )
    elif suffix == ".png":
        write_png(
            pmap, path, show_grid=show_grid, show_sectors=show_sectors, trajectories=trajectories
        )
    elif suffix == ".geojson":
        path.write_text(json.dumps(to_geojson(pmap)))
    elif suffix == ".yaml":
        from polyswarm.grids.convert import polymap_to_grid
        from polyswarm.io.mapserver import write_map

        write_map(polymap_to_grid(pmap, grid_resolution_m, wall_thickness_m=wall_thickness_m), path)
    else:
        raise PolyswarmError(f"unknown export format {suffix!r}: use one of {', '.join(SUFFIXES)}")
    return path


def to_geojson(pmap: GridPolyMap) -> dict:
    """Explored space as one Polygon feature per cell polygon, vectors as LineStrings."""
    feats = []
    for cell in pmap.cells.values():
        for poly in cell.polygons:
            rings = [np.vstack([r.xy, r.xy[:1]]).tolist() for r in poly.rings()]
            feats.append(
                {
                    "type": "Feature",
                    "properties": {"kind": "explored", "cell": list(cell.index)},
                    "geometry": {"type": "Polygon", "coordinates": rings},
                }
            )
    s, e, t = pmap.vectors()
    for kind in VectorType:
        m = t == kind
        if m.any():
            lines = np.stack([s[m], e[m]], axis=1).tolist()
            feats.append(
                {
                    "type": "Feature",
                    "properties": {"kind": kind.name.lower()},
                    "geometry": {"type": "MultiLineString", "coordinates": lines},
                }
            )
    return {"type": "FeatureCollection", "features": feats}


def to_svg(
    pmap: GridPolyMap,
    *,
    show_grid: bool = False,
    show_sectors: bool = False,
    trajectories: Sequence[np.ndarray] = (),
    margin_m: float = 1.0,
) -> str:
    x0, y0, x1, y1 = pmap.bounds()
    x0, y0, x1, y1 = x0 - margin_m, y0 - margin_m, x1 + margin_m, y1 + margin_m
    w, h = max(x1 - x0, 1e-3), max(y1 - y0, 1e-3)

    def pt(p) -> str:  # y up in the map, y down in SVG
        return f"{p[0] - x0:.3f},{y1 - p[1]:.3f}"

    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w:.3f} {h:.3f}" '
        f'width="{w * 20:.0f}" height="{h * 20:.0f}">',
        f'<rect width="{w:.3f}" height="{h:.3f}" fill="#9e9e9e"/>',
    ]
    for cell in pmap.cells.values():
        for poly in cell.polygons:
            d = " ".join("M " + " L ".join(pt(p) for p in r.xy) + " Z" for r in poly.rings())
            out.append(f'<path d="{d}" fill="{FREE_FILL}" fill-rule="evenodd" stroke="none"/>')
    if show_grid:
        s = pmap.cell_size
        for i, j in pmap.cells:
            out.append(
                f'<rect x="{i * s - x0:.3f}" y="{y1 - (j + 1) * s:.3f}" width="{s}" height="{s}" '
                'fill="none" stroke="#4a90d9" stroke-width="0.01"/>'
            )
    s_, e_, t_ = pmap.vectors()
    kinds = [VectorType.OBSTACLE, VectorType.FRONTIER] + (
        [VectorType.SECTOR] if show_sectors else []
    )
    for kind in kinds:
        m = t_ == kind
        width = 0.02 if kind == VectorType.SECTOR else 0.06
        segs = " ".join(f"M {pt(a)} L {pt(b)}" for a, b in zip(s_[m], e_[m], strict=True))
        if segs:
            out.append(
                f'<path d="{segs}" stroke="{COLOURS[kind]}" stroke-width="{width}" fill="none"/>'
            )
    if show_sectors:
        for cell in pmap.cells.values():
            for piece in partition_of(cell).pieces:
                nxt = np.roll(piece.xy, -1, axis=0)
                for a, b, ln in zip(piece.xy, nxt, piece.links, strict=True):
                    if ln >= 0:
                        out.append(
                            f'<path d="M {pt(a)} L {pt(b)}" stroke="{COLOURS[VectorType.SECTOR]}" '
                            'stroke-width="0.02"/>'
                        )
    for traj in trajectories:
        if len(traj) > 1:
            d = "M " + " L ".join(pt(p) for p in np.asarray(traj)[:, :2])
            out.append(f'<path d="{d}" stroke="#1f3fbf" stroke-width="0.04" fill="none"/>')
    out.append("</svg>")
    return "\n".join(out)


def write_png(
    pmap: GridPolyMap,
    path: str | Path,
    *,
    show_grid: bool = False,
    show_sectors: bool = False,
    trajectories: Sequence[np.ndarray] = (),
    max_pixels: int = 2000,
    title: str | None = None,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection, PatchCollection
    from matplotlib.patches import PathPatch
    from matplotlib.patches import Polygon as MplPolygon
    from matplotlib.path import Path as MplPath

    x0, y0, x1, y1 = pmap.bounds()
    w, h = max(x1 - x0, 1.0), max(y1 - y0, 1.0)
    scale = max_pixels / max(w, h)
    dpi = 100
    fig = plt.figure(figsize=(max(w * scale / dpi, 2), max(h * scale / dpi, 2)), dpi=dpi)
    ax = fig.add_axes((0.02, 0.02, 0.96, 0.93 if title else 0.96))
    ax.set_facecolor("#9e9e9e")
    patches = []
    for cell in pmap.cells.values():
        for poly in cell.polygons:
            verts, codes = [], []
            for r in poly.rings():
                verts += [*r.xy.tolist(), r.xy[0].tolist()]
                codes += [MplPath.MOVETO] + [MplPath.LINETO] * (len(r) - 1) + [MplPath.CLOSEPOLY]
            patches.append(PathPatch(MplPath(verts, codes)))
    ax.add_collection(PatchCollection(patches, facecolor=FREE_FILL, edgecolor="none"))
    if show_grid:
        s = pmap.cell_size
        boxes = [
            MplPolygon(
                [
                    (i * s, j * s),
                    ((i + 1) * s, j * s),
                    ((i + 1) * s, (j + 1) * s),
                    (i * s, (j + 1) * s),
                ]
            )
            for (i, j) in pmap.cells
        ]
        ax.add_collection(
            PatchCollection(boxes, facecolor="none", edgecolor="#4a90d9", linewidth=0.3)
        )
    s_, e_, t_ = pmap.vectors()
    lw = max(0.6, min(2.0, 0.05 * scale / 2))
    for kind in (VectorType.SECTOR, VectorType.FRONTIER, VectorType.OBSTACLE):
        if kind == VectorType.SECTOR and not show_sectors:
            continue
        m = t_ == kind
        if m.any():
            ax.add_collection(
                LineCollection(
                    np.stack([s_[m], e_[m]], axis=1),
                    colors=COLOURS[kind],
                    linewidths=lw * (0.4 if kind == VectorType.SECTOR else 1.0),
                )
            )
    for traj in map(np.asarray, trajectories):
        if len(traj) > 1:
            ax.plot(traj[:, 0], traj[:, 1], color="#1f3fbf", linewidth=lw * 0.7)
    ax.set_xlim(x0 - 0.5, x1 + 0.5)
    ax.set_ylim(y0 - 0.5, y1 + 0.5)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
