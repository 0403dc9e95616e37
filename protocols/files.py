"""``.polymap`` files: the full-map encoding of ``mapcodec`` written to disk."""

from __future__ import annotations

from pathlib import Path

from polyswarm.errors import DataFormatError, DecodeError
from polyswarm.polymap import PRECISION_M, GridPolyMap
from protocols.mapcodec import decode_map, encode_map

SUFFIX = ".polymap"


def write_polymap(pmap: GridPolyMap, path: str | Path, precision_m: float = PRECISION_M) -> int:
    """Write the map (vertices rounded to ``precision_m``); returns the bytes written."""
    data = encode_map(pmap, precision_m)
    Path(path).write_bytes(data)
    return len(data)


def read_polymap(path: str | Path) -> GridPolyMap:
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError as e:
        raise DataFormatError(f"map file not found: {p}") from e
    try:
        return decode_map(data)
    except DecodeError as e:
        raise DecodeError(f"{p}: {e}") from None
