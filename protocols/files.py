"""``.polymap`` files: the full-map encoding of ``mapcodec`` written to disk."""

from __future__ import annotations

from pathlib import Path

from polyswarm.errors import DataFormatError, DecodeError
from polyswarm.polymap import GridPolyMap
from protocols.mapcodec import decode_map, encode_map

SUFFIX = ".polymap"


def write_polymap(pmap: GridPolyMap, path: str | Path) -> int:
    data = encode_map(pmap)
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
