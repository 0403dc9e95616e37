"""The idealised exploration reference, run for the same world, robots and sensor.

``../shared/tools/explore_reference.py`` (an independent grid planner: perfect
localisation and motion, point robots on the inflated free grid, a ray-cast sensor) is
loaded as a module, given the profile's range, field of view, speed and radius and our
robot 0's start, and scored with the same coverage definition as our runs
(``polyswarm.evaluation.coverage.reachable_free``: its ground truth is the free space within the
robot's radius of its reachable cells already; the band of ``coverage_tolerance`` along
obstacles is taken off it too, as the same whole number of cells: ``raster_m``).
Procedural worlds are rasterised to map_server files first. Results are cached on disk:
the reference is deterministic.

    ref = reference_run("data:loop", 3, cfg, start_xy=(2.0, 2.0), tolerance_m=0.2)
    ref["t99_s"]
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import logging
import math
from pathlib import Path

import numpy as np
import shapely

from polyswarm.config import Config
from polyswarm.data import shared_data_dir
from polyswarm.errors import DataFormatError
from polyswarm.grids.occupancy import FREE, OCCUPIED, UNKNOWN, OccupancyGrid

log = logging.getLogger(__name__)

RASTER_M = 0.05  # procedural worlds on the grid of a typical map_server map, or finer:
CACHE_DIR = Path("runs") / "reference-cache"
STRATEGY = {1: "nearest", 3: "hungarian"}  # one robot: the reference's event-driven single


def raster_m(tolerance_m: float) -> float:
    """The cell size a procedural world is rasterised at for a coverage band of
    ``tolerance_m``: ``RASTER_M`` or finer, so that the band is a whole number of cells
    (the thesis sensor's 2 cm band would be no cell at all at 5 cm)."""
    if tolerance_m <= 0:
        return RASTER_M
    return tolerance_m / math.ceil(tolerance_m / RASTER_M - 1e-9)


def reference_module():
    """``explore_reference.py`` from the shared tools, as a module."""
    path = shared_data_dir().parent / "tools" / "explore_reference.py"
    if not path.exists():
        raise DataFormatError(f"exploration reference not found: {path}")
    spec = importlib.util.spec_from_file_location("explore_reference", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def rasterise(world, resolution_m: float = RASTER_M) -> OccupancyGrid:
    """A simulator world as an occupancy grid: walls occupied, the reachable free space
    free, the rest unknown (cell centres decide)."""
    x0, y0, x1, y1 = world.bounds
    x0, y0 = x0 - 2 * resolution_m, y0 - 2 * resolution_m
    cols = math.ceil((x1 - x0) / resolution_m) + 2
    rows = math.ceil((y1 - y0) / resolution_m) + 2
    xs = x0 + (np.arange(cols) + 0.5) * resolution_m
    ys = y0 + (np.arange(rows) + 0.5) * resolution_m
    gx, gy = np.meshgrid(xs, ys)
    data = np.full((rows, cols), UNKNOWN, dtype=np.int8)
    data[shapely.contains_xy(world.free, gx, gy)] = FREE
    data[shapely.contains_xy(world.walls, gx, gy)] = OCCUPIED
    return OccupancyGrid(data, resolution_m, (x0, y0))


def reference_run(
    world_spec: str,
    robots: int,
    cfg: Config,
    start_xy: tuple[float, float],
    tolerance_m: float,
    seed: int = 0,
    cache_dir: Path = CACHE_DIR,
) -> dict:
    """The reference's run (its JSON row: ``t90_s``, ``t99_s``, ``coverage_per_s`` ...)
    for ``robots`` robots with ``cfg``'s lidar and base, starting at ``start_xy``."""
    from sim import load_world

    world = load_world(world_spec, seed=seed)
    lid, base = cfg.sim.lidar, cfg.sim.robot
    params = {
        "world": world_spec,
        "seed": seed if world_spec in ("maze", "furnished") else 0,  # seeded layouts
        "robots": robots,
        "range_m": lid.range_max_m,
        "fov_deg": round(math.degrees(lid.fov_rad), 6),
        "speed_mps": base.max_linear_mps,
        "radius_m": base.radius_m,
        "start": [round(start_xy[0], 3), round(start_xy[1], 3)],
        "tolerance_m": round(tolerance_m, 4),
        "raster_m": None if world.grid is not None else round(raster_m(tolerance_m), 6),
        "strategy": STRATEGY.get(robots, "hungarian"),
        "reference_sha": _file_sha(shared_data_dir().parent / "tools" / "explore_reference.py"),
    }
    key = hashlib.sha256(json.dumps(params, sort_keys=True).encode()).hexdigest()[:16]
    cached = cache_dir / f"{key}.json"
    if cached.exists():
        return json.loads(cached.read_text())
    cache_dir.mkdir(parents=True, exist_ok=True)
    yaml_path = _map_file(world, world_spec, cache_dir, key, raster_m(tolerance_m))
    mod = reference_module()
    mod.RANGE, mod.FOV_DEG = params["range_m"], params["fov_deg"]
    mod.SPEED, mod.R_ROBOT = params["speed_mps"], params["radius_m"]
    name = f"ref-{key}"
    mod.WORLDS[name] = str(yaml_path)
    mod.START_ANCHOR[name] = tuple(start_xy)
    w = mod.World(name)
    band_m = _erode_truth(w, tolerance_m)
    log.info("reference: %s, %d robot(s), %s (%d truth cells)", world_spec, robots, params, w.n_gt)
    row = mod.Sim(w, params["strategy"], robots).run()
    row |= {"params": params, "truth_m2": w.n_gt * w.res**2, "band_m": band_m}
    cached.write_text(json.dumps(row))
    return row


def _map_file(world, world_spec: str, cache_dir: Path, key: str, resolution_m: float) -> Path:
    if world.grid is not None and world_spec.endswith((".yaml", ".yml")):
        return Path(world_spec).resolve()
    if world_spec.startswith("data:"):
        from polyswarm.data import world_yaml

        return world_yaml(world_spec[5:]).resolve()
    from polyswarm.io.mapserver import write_map

    path = cache_dir / f"{key}.yaml"
    write_map(rasterise(world, resolution_m), path)
    return path.resolve()


def _erode_truth(w, tolerance_m: float) -> float:
    """Take the band of ``tolerance_m`` along the truth's boundary off the reference's
    ground truth ``w.gt`` (cells of ``w.res`` metres): the nearest whole number of cells,
    those at most that many cells from one outside it. Returns the band taken off (m):
    ``tolerance_m`` itself where the raster was chosen for it (``raster_m``)."""
    from scipy import ndimage

    cells = round(tolerance_m / w.res)
    if cells <= 0:
        return 0.0
    dist = ndimage.distance_transform_edt(w.gt)  # cells to the nearest cell outside
    w.gt = dist > cells + 1e-9
    w.n_gt = int(w.gt.sum())
    return cells * w.res


def _file_sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:12]
