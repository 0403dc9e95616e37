"""Regenerate the golden vectors (run only when the format version changes).

    python -m protocols.golden.make_golden

Each ``NAME.bin`` is an encoded message; ``NAME.json`` states what it must decode to,
in integer wire units (10 um), so another implementation can check itself against it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from polyswarm.polymap import UNITS_PER_M, GridPolyMap, Ring, TypedPolygon, VectorType
from protocols.mapcodec import encode_delta, encode_map

HERE = Path(__file__).parent
O, F = VectorType.OBSTACLE, VectorType.FRONTIER


def golden_maps() -> tuple[GridPolyMap, GridPolyMap]:
    """A 3 m x 1.5 m room with a pillar, then a corridor added to it."""
    room = TypedPolygon(
        Ring([(0.5, 0.5), (3.5, 0.5), (3.5, 2.0), (0.5, 2.0)], [O, F, O, O]),
        (Ring([(1.0, 1.0), (1.0, 1.2), (1.3, 1.2), (1.3, 1.0)], [O] * 4),),
    )
    corridor = TypedPolygon(Ring([(3.4, 1.0), (6.0, 1.0), (6.0, 1.6), (3.4, 1.6)], [O, F, O, F]))
    a = GridPolyMap(2.0).merge(room).map
    b = a.merge(corridor).map
    return a, b


def units(xy: np.ndarray) -> list[list[int]]:
    return np.rint(np.asarray(xy) * UNITS_PER_M).astype(np.int64).tolist()


def describe_polygons(polys) -> list:
    return [[{"xy": units(r.xy), "types": r.types.tolist()} for r in p.rings()] for p in polys]


def main() -> None:
    a, b = golden_maps()
    (HERE / "map_v1.bin").write_bytes(encode_map(b))
    (HERE / "map_v1.json").write_text(
        json.dumps(
            {
                "type": "polymap",
                "format_version": 1,
                "cell_size_units": 200000,
                "version": b.version,
                "polygons": describe_polygons(b.dissolve()),
            },
            indent=1,
        )
    )
    delta = b.delta_since(a.version)
    (HERE / "delta_v1.bin").write_bytes(encode_delta(delta))
    (HERE / "delta_v1.json").write_text(
        json.dumps(
            {
                "type": "polymap-delta",
                "format_version": 1,
                "cell_size_units": 200000,
                "base_version": delta.base_version,
                "version": delta.version,
                "cells": [
                    {
                        "index": list(c.index),
                        "version": c.version,
                        "polygons": describe_polygons(c.polygons),
                    }
                    for c in sorted(delta.cells, key=lambda c: c.index)
                ],
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
