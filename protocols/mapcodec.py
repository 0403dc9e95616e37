"""PolyMap and delta encoding: msgpack envelope, varint-packed geometry.

Layout (normative text in ``PROTOCOL.md``)::

    map   = msgpack {"t": "polymap", "v": 1, "cs": cell size (units), "ver": n,
                     "q": quantum (units), "ox": int, "oy": int, "polys": bin}
    delta = msgpack {"t": "polymap-delta", "v": 1, "cs": cell size (units), "base": n, "ver": n,
                     "cells": bin}
    merge = msgpack {"t": "polymap-merge", "v": 1, "b": bin}     (a MergeOp, see below)
    correct = msgpack {"t": "polymap-correct", "v": 1, "b": bin}  (a CorrectionOp, below;
              "bz": zlib(bin) instead of "b" when that is smaller)

A full map carries the explored space as polygons across cell borders (the receiver
cuts them into cells again; sectors on cell borders are implied). A delta carries the
changed cells exactly. Both are sequences of unsigned varints::

    polys: n_polygons, then per polygon: n_rings, rings...   (first ring is the shell)
           vertex (x, y) in units = q * (ox + u, oy + v) with u, v >= 0
    cells: n_cells, then per cell (sorted by (i, j)):
           zz(di) zz(dj) age q n_polygons, per polygon: n_rings, rings...
           (di, dj: index step from the previous cell; age: ver - cell version;
            vertex in units = (i * cs + q * u, j * cs + q * v) with 0 <= q*u, q*v <= cs)
    ring:  n  u0 v0  h[1..n-1]  dy[1..m]  type_n
           h = zz(d) << 4 | mode << 2 | type     mode 0: step (d, 0)   mode 1: (0, d)
                                                 mode 2: (d, dy), dy read after all h
           the n-th vector closes the ring; only its type is sent

A merge (a keyframe polygon the receiver merges into its bit-identical copy of the
sender's map, ``polymap.MergeOp``) is one varint sequence::

    b: cs base ver-base digest q n_opts opts[n_opts] n_rings rings...
       opts: the MergeOptions in units, in field order; q: the polygon's quantum (units)
       ring: n zz(x0) zz(y0) h[0..n-2] zz(dy)[0..n-2] type_n-1
             h = zz(dx) << 2 | type; vertices in units = q * (x, y), absolute
       then, from a map that follows its pose graph: id (the keyframe's pose-graph id)

A correction (keyframes moved by a loop closure, ``polyswarm.slam.follow.CorrectionOp``)::

    b: cs base digest n  (did zz(ddx) zz(ddy) zz(ddtheta))[n]
       did: the id's step from the previous entry's (the first from -1: ids ascend);
       ddx ddy ddtheta: the keyframe's move from where the receiver holds it (mm and
       10 urad) less the previous entry's move (the first's from 0); version base + 1

A unit is 10 micrometres (the map's precision grid, so deltas lose nothing); ``q`` is the
largest quantum dividing all coordinates (100 units for whole maps shared at 1 mm and for
merges, 1 unit for cells, 5,000-20,000 units for converted 5-20 cm grid maps), so a
typical vector costs one to four bytes.

Decoding untrusted bytes raises ``DecodeError`` (and nothing else) on any defect, and
builds a new map object, so a bad message never touches an existing map.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import astuple, fields

import msgpack
import numpy as np
import shapely

from polyswarm.errors import DecodeError, PolyswarmError
from polyswarm.polymap import (
    PRECISION_M,
    Cell,
    GridPolyMap,
    MapDelta,
    MergeOp,
    MergeOptions,
    Ring,
    TypedPolygon,
    VectorType,
)
from polyswarm.polymap import UNITS_PER_M as POLYMAP_UNITS_PER_M
from polyswarm.slam.follow import CorrectionOp
from protocols.varint import decode_varints, encode_varints, unzigzag, zigzag

FORMAT_VERSION = 1
MAP_TYPE = "polymap"
DELTA_TYPE = "polymap-delta"
MERGE_TYPE = "polymap-merge"
CORRECTION_TYPE = "polymap-correct"
MAX_POSE_UNITS = 2**40  # mm: poses farther out are refused
MAX_ANGLE_UNITS = 400_000  # 10 urad: |theta| <= 4 rad (a sender wraps it to pi)
MAX_MOVES = 2**20  # keyframes one correction may move
UNITS_PER_M = POLYMAP_UNITS_PER_M  # wire coordinates are integers of 10 um (PRECISION_M)
MAX_OPTION_UNITS = UNITS_PER_M  # merge options above 1 m are refused
MAX_COORD_UNITS = 2**40  # about 11,000 km: coordinates and steps beyond are refused
MAX_MERGE_VERTICES = 2**20  # per ring of a merge (a keyframe has hundreds)
MAX_CELL_UNITS = 100 * UNITS_PER_M  # cells larger than 100 m are refused
MAX_MESSAGE_BYTES = 256 * 1024 * 1024


def _units(xy: np.ndarray) -> np.ndarray:
    return np.rint(np.asarray(xy) * UNITS_PER_M).astype(np.int64)


def _encode_cells(cells: list[Cell], version: int, cell_u: int) -> bytes:
    vals: list[np.ndarray] = [np.array([len(cells)], dtype=np.int64)]
    pi, pj = 0, 0
    for cell in sorted(cells, key=lambda c: c.index):
        i, j = cell.index
        origin = np.array([i * cell_u, j * cell_u], dtype=np.int64)
        local = [_units(r.xy) - origin for p in cell.polygons for r in p.rings()]
        q = int(np.gcd.reduce(np.concatenate([x.ravel() for x in local]))) if local else 1
        q = max(q, 1)
        head = [zigzag(i - pi), zigzag(j - pj), version - cell.version, q, len(cell.polygons)]
        vals.append(np.array(head, dtype=np.int64))
        pi, pj = i, j
        k = 0
        for poly in cell.polygons:
            vals.append(np.array([len(poly.rings())], dtype=np.int64))
            for ring in poly.rings():
                vals.append(_encode_ring(local[k] // q, ring.types))
                k += 1
    return encode_varints(np.concatenate(vals).astype(np.uint64))


def _encode_ring(v: np.ndarray, types: np.ndarray) -> np.ndarray:
    d = np.diff(v, axis=0)  # n-1 steps; the closing vector is implicit
    horiz = d[:, 1] == 0
    vert = (d[:, 0] == 0) & ~horiz
    mode = np.where(horiz, 0, np.where(vert, 1, 2))
    primary = np.where(vert, d[:, 1], d[:, 0])
    h = (zigzag(primary).astype(np.int64) << 4) | (mode << 2) | types[:-1].astype(np.int64)
    extra = zigzag(d[mode == 2, 1]).astype(np.int64)
    return np.concatenate([[len(v), v[0, 0], v[0, 1]], h, extra, [int(types[-1])]])


def encode_map(pmap: GridPolyMap, precision_m: float = PRECISION_M) -> bytes:
    """A full map: its explored space dissolved across cell borders, its vertices rounded
    to ``precision_m`` (the default keeps the map's 10 um; whole maps that are shared or
    saved go at ``MapConfig.whole_map_precision_m``, 1 mm, which makes them a third
    smaller: ``q`` becomes 100 units)."""
    cell_u = _cell_units(pmap.cell_size)
    polys = pmap.dissolve(precision_m)
    rings_u = [[_units(r.xy) for r in p.rings()] for p in polys]
    flat = np.concatenate([x for rs in rings_u for x in rs]) if polys else np.zeros((1, 2), int)
    q = max(int(np.gcd.reduce(flat.ravel())), 1)
    o = flat.min(axis=0) // q
    vals = [np.array([len(polys)], dtype=np.int64)]
    for p, rs in zip(polys, rings_u, strict=True):
        vals.append(np.array([len(rs)], dtype=np.int64))
        for ring, xy in zip(p.rings(), rs, strict=True):
            vals.append(_encode_ring(xy // q - o, ring.types))
    body = encode_varints(np.concatenate(vals).astype(np.uint64))
    return msgpack.packb(
        {
            "t": MAP_TYPE,
            "v": FORMAT_VERSION,
            "cs": cell_u,
            "ver": pmap.version,
            "q": q,
            "ox": int(o[0]),
            "oy": int(o[1]),
            "polys": body,
        }
    )


def encode_delta(delta: MapDelta) -> bytes:
    cell_u = _cell_units(delta.cell_size)
    body = _encode_cells(list(delta.cells), delta.version, cell_u)
    return msgpack.packb(
        {
            "t": DELTA_TYPE,
            "v": FORMAT_VERSION,
            "cs": cell_u,
            "base": delta.base_version,
            "ver": delta.version,
            "cells": body,
        }
    )


def encode_merge(op: MergeOp) -> bytes:
    """A merge operation; its polygon's vertices must lie on a grid of whole units."""
    rings = op.polygon.rings()
    units = [_units(r.xy) for r in rings]
    for r, u in zip(rings, units, strict=True):
        if np.abs(u / UNITS_PER_M - r.xy).max() > 0:
            raise PolyswarmError("merge polygon is not on the 10 um grid (snap_polygon it)")
    q = max(int(np.gcd.reduce(np.concatenate([u.ravel() for u in units]))), 1)
    opts = [round(v * UNITS_PER_M) for v in astuple(op.options)]
    head = [_cell_units(op.cell_size), op.base_version, op.version - op.base_version, op.digest]
    vals = [np.array([*head, q, len(opts), *opts, len(rings)], dtype=np.int64)]
    for r, u in zip(rings, units, strict=True):
        v = u // q
        d = np.diff(v, axis=0)
        h = (zigzag(d[:, 0]).astype(np.int64) << 2) | r.types[:-1].astype(np.int64)
        vals.append(
            np.concatenate([[len(v)], zigzag(v[0]), h, zigzag(d[:, 1]), [int(r.types[-1])]])
        )
    if op.keyframe is not None:
        vals.append(np.array([op.keyframe], dtype=np.int64))
    body = encode_varints(np.concatenate(vals).astype(np.uint64))
    return msgpack.packb({"t": MERGE_TYPE, "v": FORMAT_VERSION, "b": body})


def encode_correction(op: CorrectionOp) -> bytes:
    """A correction: the keyframes a loop closure moved, as poses."""
    if op.version != op.base_version + 1:
        raise PolyswarmError("a correction steps the map's version by one")
    rows = np.array([[k, *q] for k, q in op.moves], dtype=np.int64).reshape(-1, 4)
    ids = np.diff(np.concatenate([[-1], rows[:, 0]]))
    if (ids <= 0).any():
        raise PolyswarmError("a correction's keyframe ids must ascend")
    # consecutive keyframes move alike: each move as its difference from the previous one's
    moves = np.diff(np.vstack([np.zeros((1, 3), dtype=np.int64), rows[:, 1:]]), axis=0)
    cols = np.column_stack([ids.astype(np.uint64), zigzag(moves).reshape(-1, 3)])
    head = [_cell_units(op.cell_size), op.base_version, op.digest, len(rows)]
    body = encode_varints(np.concatenate([np.array(head, dtype=np.uint64), cols.ravel()]))
    packed = zlib.compress(body, 9)  # the moves repeat themselves: 39 % smaller on aces
    if len(packed) < len(body):
        return msgpack.packb({"t": CORRECTION_TYPE, "v": FORMAT_VERSION, "bz": packed})
    return msgpack.packb({"t": CORRECTION_TYPE, "v": FORMAT_VERSION, "b": body})


def encode_update(
    delta: MapDelta, op: MergeOp | None, cells: bytes | None = None
) -> tuple[str, bytes]:
    """What a robot sends for one map change: the merge when it is the smaller, else the
    changed cells (``cells``: the delta already encoded). A merge of a keyframe (a map
    that follows its pose graph) always goes as the merge: every receiver must hold the
    keyframe to follow later corrections. Returns (``MERGE_TYPE`` or ``DELTA_TYPE``,
    payload)."""
    if op is not None and op.keyframe is not None:
        return MERGE_TYPE, encode_merge(op)
    cells = encode_delta(delta) if cells is None else cells
    if op is None:
        return DELTA_TYPE, cells
    merge = encode_merge(op)
    return (MERGE_TYPE, merge) if len(merge) < len(cells) else (DELTA_TYPE, cells)


def encode_updates(
    delta: MapDelta,
    op: MergeOp | None,
    correction: CorrectionOp | None = None,
    cells: bytes | None = None,
) -> list[tuple[str, int, int, bytes]]:
    """What a robot sends for one keyframe step, in order: (message type, base version,
    version, payload). After a loop closure (``correction``) the correction goes first,
    then the merge (or the cells it changed)."""
    if correction is None:
        what, payload = encode_update(delta, op, cells)
        return [(what, delta.base_version, delta.version, payload)]
    out = [
        (
            CORRECTION_TYPE,
            correction.base_version,
            correction.version,
            encode_correction(correction),
        )
    ]
    if delta.version > correction.version:
        rest = MapDelta(
            delta.cell_size,
            correction.version,
            delta.version,
            tuple(c for c in delta.cells if c.version > correction.version),
        )
        what, payload = encode_update(rest, op)
        out.append((what, rest.base_version, rest.version, payload))
    return out


def encode_cells_map(pmap: GridPolyMap) -> bytes:
    """A whole map as its cells, exactly (a delta from version -1): a copy made from it
    is bit-identical, so merge operations replay on it. ``encode_map`` is smaller."""
    return encode_delta(pmap.delta_since(-1))


def _cell_units(cell_size: float) -> int:
    units = round(cell_size * UNITS_PER_M)
    if abs(units - cell_size * UNITS_PER_M) > 1e-6 or not (1 <= units <= MAX_CELL_UNITS):
        raise PolyswarmError(f"cell size {cell_size} m is not a whole number of 10 um units")
    return units


# ---------------------------------------------------------------------------------------
# Decoding (untrusted input)
# ---------------------------------------------------------------------------------------


def _unpack(data: bytes, kind: str, *others: str) -> dict:
    """The message's msgpack map, of type ``kind`` (or one of ``others``)."""
    if not isinstance(data, bytes | bytearray | memoryview):
        raise DecodeError(f"{kind}: expected bytes, got {type(data).__name__}")
    if len(data) > MAX_MESSAGE_BYTES:
        raise DecodeError(f"{kind}: message of {len(data)} bytes is too large")
    try:
        obj = msgpack.unpackb(bytes(data), raw=False, strict_map_key=True)
    except Exception as e:  # msgpack raises many types on garbage
        raise DecodeError(f"{kind}: not valid msgpack ({type(e).__name__}: {e})") from None
    if not isinstance(obj, dict):
        raise DecodeError(f"{kind}: expected a msgpack map")
    if obj.get("t") not in (kind, *others):
        raise DecodeError(f"expected message type {kind!r}, got {obj.get('t')!r}")
    if obj.get("v") != FORMAT_VERSION:
        raise DecodeError(f"{kind}: unsupported format version {obj.get('v')!r}")
    return obj


def _int_field(obj: dict, key: str, lo: int, hi: int) -> int:
    v = obj.get(key)
    if isinstance(v, bool) or not isinstance(v, int) or not (lo <= v <= hi):
        raise DecodeError(f"field {key!r} must be an integer in [{lo}, {hi}], got {v!r}")
    return v


def decode_map(data: bytes) -> GridPolyMap:
    """Decode a full map; any defect raises ``DecodeError``."""
    return _map_from(_unpack(data, MAP_TYPE))


def _map_from(obj: dict) -> GridPolyMap:
    cell_u = _int_field(obj, "cs", 1, MAX_CELL_UNITS)
    version = _int_field(obj, "ver", 0, 2**62)
    q = _int_field(obj, "q", 1, 2**30)
    ox = _int_field(obj, "ox", -(2**40), 2**40)
    oy = _int_field(obj, "oy", -(2**40), 2**40)
    body = obj.get("polys")
    if not isinstance(body, bytes):
        raise DecodeError("field 'polys' must be binary")
    r = _Reader(decode_varints(body))
    polys = []
    origin = np.array([ox * q, oy * q], dtype=np.int64)
    for k in range(r.one("polygon count", 0, len(r.vals))):
        n_rings = r.one("ring count", 1, len(r.vals))
        rings = [_decode_ring(r, q, 2**40, None, origin) for _ in range(n_rings)]
        poly = TypedPolygon(rings[0], tuple(rings[1:]))
        try:
            poly.validate()
        except PolyswarmError as e:
            raise DecodeError(f"polygon {k}: {e}") from None
        polys.append(poly)
    if r.pos != len(r.vals):
        raise DecodeError(f"{len(r.vals) - r.pos} trailing values after the last polygon")
    try:
        return GridPolyMap.from_polygons(polys, cell_u / UNITS_PER_M, version)
    except PolyswarmError as e:
        raise DecodeError(f"map cannot be rebuilt: {e}") from None


def decode_delta(data: bytes) -> MapDelta:
    """Decode a delta; any defect raises ``DecodeError``."""
    return _delta_from(_unpack(data, DELTA_TYPE))


def _delta_from(obj: dict) -> MapDelta:
    cell_u = _int_field(obj, "cs", 1, MAX_CELL_UNITS)
    version = _int_field(obj, "ver", 0, 2**62)
    base = _int_field(obj, "base", -1, version)
    cells = _decode_cells(obj.get("cells"), cell_u, version)
    return MapDelta(cell_u / UNITS_PER_M, base, version, tuple(cells))


def decode_merge(data: bytes) -> MergeOp:
    """Decode a merge operation; any defect raises ``DecodeError``."""
    obj = _unpack(data, MERGE_TYPE)
    body = obj.get("b")
    if not isinstance(body, bytes):
        raise DecodeError("field 'b' must be binary")
    r = _Reader(decode_varints(body))
    cell_u = r.one("cell size", 1, MAX_CELL_UNITS)
    base = r.one("base version", 0, 2**62)
    version = base + r.one("version step", 1, 2**62)
    digest = r.one("digest", 0, 2**32 - 1)
    q = r.one("quantum", 1, cell_u)
    n_opts = len(fields(MergeOptions))
    r.one("option count", n_opts, n_opts)
    opts = [r.one("merge option", 0, MAX_OPTION_UNITS) / UNITS_PER_M for _ in range(n_opts)]
    n_rings = r.one("ring count", 1, len(r.vals))
    rings = []
    for k in range(n_rings):
        n = r.one("vertex count", 3, min(len(r.vals), MAX_MERGE_VERTICES))
        x0, y0 = unzigzag(r.take(2, "first vertex"))
        h = r.take(n - 1, "vectors").astype(np.uint64)
        dy = unzigzag(r.take(n - 1, "y steps"))
        last = r.one("closing vector type", 0, int(VectorType.SECTOR))
        ty = (h & np.uint64(3)).astype(np.int64)
        if (ty > VectorType.SECTOR).any():
            raise DecodeError(f"ring {k}: unknown vector type")
        dx = unzigzag(h >> np.uint64(2))
        steps = np.stack([dx, dy], axis=1)
        # bounded before summing, so that no int64 overflows (2**20 steps of 2**40)
        if max(abs(int(x0)), abs(int(y0)), int(np.abs(steps).max())) > MAX_COORD_UNITS // q:
            raise DecodeError(f"ring {k}: vertex or step too far")
        v = np.vstack([[x0, y0], np.array([x0, y0]) + np.cumsum(steps, axis=0)])
        if int(np.abs(v).max()) > MAX_COORD_UNITS // q:
            raise DecodeError(f"ring {k}: vertex too far from the origin")
        rings.append(Ring(v * q / UNITS_PER_M, np.append(ty, last).astype(np.uint8)))
    keyframe = r.one("keyframe id", 0, 2**62) if r.pos != len(r.vals) else None
    if r.pos != len(r.vals):
        raise DecodeError(f"{len(r.vals) - r.pos} trailing values after the last ring")
    poly = TypedPolygon(rings[0], tuple(rings[1:]))
    try:
        poly.validate()
    except PolyswarmError as e:
        raise DecodeError(f"merge polygon: {e}") from None
    return MergeOp(cell_u / UNITS_PER_M, base, version, poly, MergeOptions(*opts), digest, keyframe)


def _inflate(data, field: str) -> bytes:
    """zlib data, at most ``MAX_MESSAGE_BYTES`` once inflated."""
    if not isinstance(data, bytes):
        raise DecodeError(f"field {field!r} must be binary")
    d = zlib.decompressobj()
    try:
        out = d.decompress(data, MAX_MESSAGE_BYTES)
    except zlib.error as e:
        raise DecodeError(f"field {field!r}: not zlib data ({e})") from None
    if d.unconsumed_tail or not d.eof:
        raise DecodeError(f"field {field!r}: truncated or too large once inflated")
    return out


def _pose(v: np.ndarray, what: str) -> tuple[int, int, int]:
    x, y, th = (int(a) for a in v)
    if max(abs(x), abs(y)) > MAX_POSE_UNITS or abs(th) > MAX_ANGLE_UNITS:
        raise DecodeError(f"{what} out of range: {(x, y, th)}")
    return x, y, th


def decode_correction(data: bytes) -> CorrectionOp:
    """Decode a correction; any defect raises ``DecodeError``."""
    obj = _unpack(data, CORRECTION_TYPE)
    body = obj.get("b") if "bz" not in obj else _inflate(obj.get("bz"), "bz")
    if not isinstance(body, bytes):
        raise DecodeError("field 'b' must be binary")
    r = _Reader(decode_varints(body))
    cell_u = r.one("cell size", 1, MAX_CELL_UNITS)
    base = r.one("base version", 0, 2**62 - 1)
    digest = r.one("digest", 0, 2**32 - 1)
    n = r.one("keyframe count", 1, min(MAX_MOVES, len(r.vals)))
    vals = r.take(4 * n, "keyframe moves").reshape(n, 4)
    if r.pos != len(r.vals):
        raise DecodeError(f"{len(r.vals) - r.pos} trailing values after the last keyframe")
    # bounded before summing, so that no int64 overflows (2**20 steps of 2**40)
    if ((vals[:, 0] < 1) | (vals[:, 0] > MAX_POSE_UNITS)).any():
        raise DecodeError("keyframe id steps must be 1 to 2**40")
    ids = np.cumsum(vals[:, 0].astype(np.int64)) - 1
    diffs = unzigzag(vals[:, 1:])
    if ((diffs < -2 * MAX_POSE_UNITS) | (diffs > 2 * MAX_POSE_UNITS)).any():
        raise DecodeError("keyframe move differences too large")
    steps = np.cumsum(diffs, axis=0)
    moves = tuple(
        (int(k), _pose(d, f"move of keyframe {k}")) for k, d in zip(ids, steps, strict=True)
    )
    return CorrectionOp(cell_u / UNITS_PER_M, base, base + 1, moves, digest)


def decode_any_map(data: bytes) -> GridPolyMap:
    """A whole map sent as a ``polymap`` or as all its cells (``encode_cells_map``)."""
    obj = _unpack(data, MAP_TYPE, DELTA_TYPE)
    if obj["t"] == MAP_TYPE:
        return _map_from(obj)
    delta = _delta_from(obj)
    if delta.base_version != -1:
        raise DecodeError(f"a whole map must be a delta from version -1, not {delta.base_version}")
    try:
        return GridPolyMap(delta.cell_size).apply_delta(delta)
    except PolyswarmError as e:
        raise DecodeError(f"map cannot be rebuilt: {e}") from None


class _Reader:
    def __init__(self, vals: np.ndarray) -> None:
        self.vals = vals
        self.pos = 0

    def take(self, n: int, what: str) -> np.ndarray:
        if n < 0 or self.pos + n > len(self.vals):
            raise DecodeError(f"truncated cell data while reading {what}")
        out = self.vals[self.pos : self.pos + n]
        self.pos += n
        return out

    def one(self, what: str, lo: int = 0, hi: int = 2**62) -> int:
        v = int(self.take(1, what)[0])
        if not (lo <= v <= hi):
            raise DecodeError(f"{what} out of range: {v}")
        return v


def _decode_cells(body, cell_u: int, version: int) -> list[Cell]:
    if not isinstance(body, bytes):
        raise DecodeError("field 'cells' must be binary")
    vals = decode_varints(body)
    r = _Reader(vals)
    n_cells = r.one("cell count", 0, len(vals))
    cells = []
    seen = set()
    i = j = 0
    size = cell_u / UNITS_PER_M
    for _ in range(n_cells):
        i += int(unzigzag(np.array([r.one("cell index")]))[0])
        j += int(unzigzag(np.array([r.one("cell index")]))[0])
        if abs(i) > 2**40 or abs(j) > 2**40:
            raise DecodeError(f"absurd cell index ({i}, {j})")
        if (i, j) in seen:
            raise DecodeError(f"cell ({i}, {j}) appears twice")
        seen.add((i, j))
        age = r.one("cell age", 0, version)
        q = r.one("quantum", 1, cell_u)
        n_polys = r.one("polygon count", 0, len(vals))
        polys = []
        for _p in range(n_polys):
            n_rings = r.one("ring count", 1, len(vals))
            origin = np.array([i * cell_u, j * cell_u], dtype=np.int64)
            rings = [_decode_ring(r, q, cell_u, (i, j), origin) for _ in range(n_rings)]
            polys.append(TypedPolygon(rings[0], tuple(rings[1:])))
        cell = Cell((i, j), size, tuple(polys), version - age)
        _check_cell(cell)
        cells.append(cell)
    if r.pos != len(vals):
        raise DecodeError(f"{len(vals) - r.pos} trailing values after the last cell")
    return cells


def _decode_ring(r: _Reader, q: int, limit_u: int, ix, origin: np.ndarray) -> Ring:
    n = r.one("vertex count", 3, len(r.vals))
    x0, y0 = int(r.take(1, "x0")[0]), int(r.take(1, "y0")[0])
    h = r.take(n - 1, "vectors")
    ty = h & 3
    mode = (h >> 2) & 3
    if (ty > VectorType.SECTOR).any() or (mode == 3).any():
        raise DecodeError("unknown vector type or mode")
    primary = unzigzag((h >> 4).astype(np.uint64))
    m = int((mode == 2).sum())
    extra = unzigzag(r.take(m, "diagonal steps").astype(np.uint64))
    dx = np.where(mode == 1, 0, primary)
    dy = np.where(mode == 0, 0, np.where(mode == 1, primary, 0))
    dy[mode == 2] = extra
    last = r.one("closing vector type", 0, int(VectorType.SECTOR))
    steps = np.stack([dx, dy], axis=1)
    v = np.vstack([[x0, y0], np.array([x0, y0]) + np.cumsum(steps, axis=0)])
    where = f"cell {ix}" if ix is not None else "polygon"
    if (v < 0).any() or (v > limit_u // q).any():
        raise DecodeError(f"{where}: vertex outside the cell or map")
    if np.array_equal(v[-1], v[0]) or (steps == 0).all(axis=1).any():
        raise DecodeError(f"{where}: zero-length vector (open or degenerate ring)")
    xy = (v * q + origin) / UNITS_PER_M  # k / 100000 exactly as GEOS rounds to the grid
    return Ring(xy, np.append(ty, last).astype(np.uint8))


def _check_cell(cell: Cell) -> None:
    for k, p in enumerate(cell.polygons):
        try:
            p.validate()
        except PolyswarmError as e:
            raise DecodeError(f"cell {cell.index} polygon {k}: {e}") from None
    if len(cell.polygons) > 1:
        geom = shapely.MultiPolygon([p.to_shapely() for p in cell.polygons])
        if not geom.is_valid:
            raise DecodeError(f"cell {cell.index}: polygons overlap")
    if cell.polygons:
        x0, y0, x1, y1 = cell.bounds
        bx = shapely.bounds(cell.region)
        tol = PRECISION_M / 2
        if bx[0] < x0 - tol or bx[1] < y0 - tol or bx[2] > x1 + tol or bx[3] > y1 + tol:
            raise DecodeError(f"cell {cell.index}: geometry outside the cell")
    if not all(math.isfinite(v) for v in cell.bounds):
        raise DecodeError(f"cell {cell.index}: non-finite bounds")
