"""ROS map_server maps: a PGM (or PNG) image plus a YAML description.

Pixel to occupancy follows map_server's trinary mode: p = (255 - v) / 255 (or v / 255
with ``negate: 1``); p > occupied_thresh is occupied, p < free_thresh is free, the rest
unknown. Image rows run top-down, so the first image row is the highest y.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import yaml
from PIL import Image, UnidentifiedImageError

from polyswarm.errors import DataFormatError
from polyswarm.grids.occupancy import FREE, OCCUPIED, UNKNOWN, OccupancyGrid

log = logging.getLogger(__name__)

PGM_FREE = 254
PGM_OCCUPIED = 0
PGM_UNKNOWN = 205


def read_map(yaml_path: str | Path) -> OccupancyGrid:
    """Read a map_server YAML and its image into an ``OccupancyGrid``."""
    path = Path(yaml_path)
    try:
        meta = yaml.safe_load(path.read_text())
    except FileNotFoundError as e:
        raise DataFormatError(f"map file not found: {path}") from e
    except yaml.YAMLError as e:
        raise DataFormatError(f"{path}: invalid YAML: {e}") from e
    if not isinstance(meta, dict):
        raise DataFormatError(f"{path}: expected a YAML mapping")
    for key in ("image", "resolution", "origin"):
        if key not in meta:
            raise DataFormatError(f"{path}: missing key {key!r}")
    try:
        res = float(meta["resolution"])
        origin = [float(v) for v in meta["origin"]]
        occ_t = float(meta.get("occupied_thresh", 0.65))
        free_t = float(meta.get("free_thresh", 0.196))
        negate = int(meta.get("negate", 0))
    except (TypeError, ValueError) as e:
        raise DataFormatError(f"{path}: bad numeric field: {e}") from e
    if len(origin) < 2:
        raise DataFormatError(f"{path}: origin needs x and y")
    if len(origin) > 2 and abs(origin[2]) > 1e-9:
        raise DataFormatError(f"{path}: rotated map origins (yaw != 0) are not supported")
    image = path.parent / str(meta["image"])
    try:
        with Image.open(image) as im:
            pix = np.array(im.convert("L"), dtype=np.float64)
    except (FileNotFoundError, UnidentifiedImageError, OSError) as e:
        raise DataFormatError(f"{path}: cannot read image {image}: {e}") from e
    p = pix / 255.0 if negate else (255.0 - pix) / 255.0
    data = np.full(pix.shape, UNKNOWN, dtype=np.int8)
    data[p > occ_t] = OCCUPIED
    data[p < free_t] = FREE
    log.debug("read %s: %s cells at %.3f m", path, data.shape, res)
    return OccupancyGrid(np.flipud(data), res, (origin[0], origin[1]))


def write_map(grid: OccupancyGrid, yaml_path: str | Path) -> None:
    """Write ``grid`` as map_server PGM + YAML (image named after the YAML file)."""
    path = Path(yaml_path)
    pgm = path.with_suffix(".pgm")
    img = np.full(grid.shape, PGM_UNKNOWN, dtype=np.uint8)
    img[grid.data == FREE] = PGM_FREE
    img[grid.data == OCCUPIED] = PGM_OCCUPIED
    Image.fromarray(np.flipud(img), mode="L").save(pgm)
    meta = {
        "image": pgm.name,
        "resolution": float(grid.resolution),
        "origin": [float(grid.origin[0]), float(grid.origin[1]), 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    path.write_text(yaml.safe_dump(meta, sort_keys=False))


def grid_png_bytes(grid: OccupancyGrid) -> bytes:
    """The grid as an 8-bit greyscale PNG (map_server pixel values), for size comparisons."""
    import io

    img = np.full(grid.shape, PGM_UNKNOWN, dtype=np.uint8)
    img[grid.data == FREE] = PGM_FREE
    img[grid.data == OCCUPIED] = PGM_OCCUPIED
    buf = io.BytesIO()
    Image.fromarray(np.flipud(img), mode="L").save(buf, format="PNG", optimize=True)
    return buf.getvalue()
