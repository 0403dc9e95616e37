"""Map and delta encoding: round trips, golden vectors, and hostile input."""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import msgpack
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from polyswarm.errors import DecodeError, PolyswarmError
from polyswarm.polymap import (
    UNITS_PER_M,
    GridPolyMap,
    MergeOp,
    MergeOptions,
    VectorType,
    snap_polygon,
)
from protocols.golden.make_golden import describe_polygons, golden_maps, golden_merge
from protocols.mapcodec import (
    DELTA_TYPE,
    MERGE_TYPE,
    decode_any_map,
    decode_delta,
    decode_map,
    decode_merge,
    encode_cells_map,
    encode_delta,
    encode_map,
    encode_merge,
    encode_update,
)
from protocols.varint import decode_varints, encode_varints, unzigzag, zigzag
from tests.conftest import F, O, rect, star

GOLDEN = Path(__file__).resolve().parents[1] / "protocols" / "golden"


def sample_map() -> GridPolyMap:
    pmap = GridPolyMap(2.0)
    rng = np.random.default_rng(7)
    for _ in range(12):
        c = rng.uniform(-4, 4, 2)
        r = rng.uniform(0.5, 3, 24)
        pmap = pmap.merge(star(c, r, rng.integers(0, 2, 24))).map
    return pmap


def test_varints_round_trip():
    v = np.array([0, 1, 127, 128, 300, 2**35, 2**62], dtype=np.uint64)
    assert np.array_equal(decode_varints(encode_varints(v)), v.astype(np.int64))
    s = np.array([0, -1, 1, -(2**40), 2**40])
    assert np.array_equal(unzigzag(zigzag(s)), s)
    assert encode_varints(np.array([300])) == b"\xac\x02"


def test_full_map_round_trip_keeps_explored_space():
    pmap = sample_map()
    back = decode_map(encode_map(pmap))
    assert back.version == pmap.version and back.cell_size == pmap.cell_size
    assert back.explored_area() == pytest.approx(pmap.explored_area(), rel=1e-9)
    for kind in ("obstacle", "frontier"):
        s0 = pmap.vector_counts()[kind]
        assert s0 == 0 or back.vector_counts()[kind] > 0
    pts = np.random.default_rng(1).uniform(-8, 8, (2000, 2))
    assert np.array_equal(back.is_free_many(pts), pmap.is_free_many(pts))


def test_a_whole_map_at_1_mm_is_smaller_and_keeps_space_and_walls():
    pmap = sample_map()
    exact, coarse = encode_map(pmap), encode_map(pmap, 0.001)
    assert len(coarse) < 0.8 * len(exact)
    assert msgpack.unpackb(coarse)["q"] % 100 == 0  # every vertex on the millimetre grid
    back = decode_map(coarse)
    assert back.explored_area() == pytest.approx(pmap.explored_area(), rel=1e-4)

    def obstacle_length(m):
        s, e, _ = m.vectors([VectorType.OBSTACLE])
        return float(np.hypot(*(e - s).T).sum())

    assert obstacle_length(back) == pytest.approx(obstacle_length(pmap), rel=0.01)
    pts = np.random.default_rng(2).uniform(-8, 8, (2000, 2))
    assert (back.is_free_many(pts) != pmap.is_free_many(pts)).sum() <= 2  # within 1 mm


def test_delta_round_trip_is_exact():
    a = sample_map()
    b = a.merge(rect(3.3, -1.0, 9.1, 2.5, (O, F, O, F))).map
    delta = b.delta_since(a.version)
    back = decode_delta(encode_delta(delta))
    assert (back.base_version, back.version) == (a.version, b.version)
    copy = a.apply_delta(back)
    assert all(copy.cells[k].same_content(b.cells[k]) for k in b.cells)
    assert all(copy.cells[k].version == b.cells[k].version for k in b.cells)


def test_golden_vectors_decode_to_their_description():
    m = json.loads((GOLDEN / "map_v1.json").read_text())
    pmap = decode_map((GOLDEN / "map_v1.bin").read_bytes())
    assert (
        pmap.version == m["version"] and round(pmap.cell_size * UNITS_PER_M) == m["cell_size_units"]
    )
    assert describe_polygons(pmap.dissolve()) == m["polygons"]
    d = json.loads((GOLDEN / "delta_v1.json").read_text())
    delta = decode_delta((GOLDEN / "delta_v1.bin").read_bytes())
    assert (delta.base_version, delta.version) == (d["base_version"], d["version"])
    got = [
        {"index": list(c.index), "version": c.version, "polygons": describe_polygons(c.polygons)}
        for c in delta.cells
    ]
    assert got == d["cells"]


def test_encoder_reproduces_the_golden_bytes():
    a, b = golden_maps()
    assert encode_map(b) == (GOLDEN / "map_v1.bin").read_bytes()
    assert encode_delta(b.delta_since(a.version)) == (GOLDEN / "delta_v1.bin").read_bytes()


def test_merge_round_trip_and_replay_give_the_senders_cells():
    a, op = golden_merge()
    back = decode_merge(encode_merge(op))
    assert (back.base_version, back.version, back.digest) == (
        op.base_version,
        op.version,
        op.digest,
    )
    assert back.options == op.options and back.cell_size == op.cell_size
    assert np.array_equal(back.polygon.shell.xy, op.polygon.shell.xy)
    assert np.array_equal(back.polygon.shell.types, op.polygon.shell.types)
    want = a.merge(op.polygon, op.options).map
    got = a.replay(back).map
    assert all(got.cells[k].same_content(want.cells[k]) for k in want.cells)


def test_golden_merge_vector():
    _, op = golden_merge()
    assert encode_merge(op) == (GOLDEN / "merge_v1.bin").read_bytes()
    m = json.loads((GOLDEN / "merge_v1.json").read_text())
    back = decode_merge((GOLDEN / "merge_v1.bin").read_bytes())
    assert [back.base_version, back.version, back.digest] == [
        m["base_version"],
        m["version"],
        m["digest"],
    ]
    assert describe_polygons([back.polygon])[0] == m["polygon"]


def test_a_robot_sends_the_smaller_of_merge_and_cells():
    a = sample_map()
    kf = snap_polygon(star((1.0, 0.5), np.full(40, 2.5), np.zeros(40, dtype=np.uint8)), 100)
    res = a.merge(kf)
    delta = res.map.delta_since(a.version)
    op = MergeOp(2.0, a.version, res.map.version, kf, MergeOptions(), 0)
    what, payload = encode_update(delta, op)
    merge, cells = encode_merge(op), encode_delta(delta)
    assert (what, payload) == (
        (MERGE_TYPE, merge) if len(merge) < len(cells) else (DELTA_TYPE, cells)
    )
    assert encode_update(delta, None) == (DELTA_TYPE, cells)
    with pytest.raises(PolyswarmError, match="10 um grid"):  # never an inexact polygon
        encode_merge(MergeOp(2.0, 0, 1, star((0, 0), np.full(5, 1.0), [O] * 5), MergeOptions(), 0))


def test_a_whole_map_as_its_cells_decodes_bit_identical():
    pmap = sample_map()
    back = decode_any_map(encode_cells_map(pmap))
    assert back.version == pmap.version and set(back.cells) == set(pmap.cells)
    assert all(back.cells[k].same_content(pmap.cells[k]) for k in pmap.cells)
    assert decode_any_map(encode_map(pmap)).explored_area() == pytest.approx(pmap.explored_area())
    part = encode_delta(pmap.delta_since(1))
    with pytest.raises(DecodeError, match="version -1"):
        decode_any_map(part)


# --- hostile input ---------------------------------------------------------------------


def test_every_truncation_raises_decode_error_only():
    for blob, decode in (
        ((GOLDEN / "map_v1.bin").read_bytes(), decode_map),
        ((GOLDEN / "delta_v1.bin").read_bytes(), decode_delta),
        ((GOLDEN / "merge_v1.bin").read_bytes(), decode_merge),
        ((GOLDEN / "delta_v1.bin").read_bytes(), decode_any_map),
    ):
        for n in range(len(blob)):
            with pytest.raises(DecodeError):
                decode(blob[:n])


@given(st.binary(max_size=300))
def test_random_bytes_raise_decode_error_only(data):
    for decode in (decode_map, decode_delta, decode_merge, decode_any_map):
        with contextlib.suppress(DecodeError):
            decode(data)


@given(st.integers(0, 10_000), st.integers(0, 255))
def test_flipped_bytes_never_crash(pos, value):
    for name, decode in (("delta_v1.bin", decode_delta), ("merge_v1.bin", decode_merge)):
        blob = bytearray((GOLDEN / name).read_bytes())
        blob[pos % len(blob)] = value
        with contextlib.suppress(DecodeError):
            decode(bytes(blob))


def _delta_with_body(body: bytes, **fields) -> bytes:
    msg = {"t": "polymap-delta", "v": 1, "cs": 200000, "base": 0, "ver": 1, "cells": body}
    msg.update(fields)
    return msgpack.packb(msg)


def _cell(ring_vals: list[int], q: int = 1000) -> bytes:
    # one cell (0, 0), age 0, quantum q, one polygon with one ring
    return encode_varints(np.array([1, 0, 0, 0, q, 1, 1, *ring_vals], dtype=np.uint64))


def _z(v: int) -> int:
    return int(zigzag(np.array([v]))[0])


def _h(d: int, mode: int, t: int) -> int:
    return (_z(d) << 4) | (mode << 2) | t


GOOD_RING = [4, 10, 10, _h(50, 0, 0), _h(50, 1, 0), _h(-50, 0, 0), 0]  # 0.5 m square


@pytest.mark.parametrize(
    ("msg", "match"),
    [
        (b"\xc1", "not valid msgpack"),
        (msgpack.packb([1, 2]), "msgpack map"),
        (msgpack.packb({"t": "polymap-delta", "v": 2}), "format version"),
        (_delta_with_body(b"", cs="x"), "'cs'"),
        (_delta_with_body(b"", cs=float("nan")), "'cs'"),
        (_delta_with_body(b"", ver=-3), "'ver'"),
        (_delta_with_body(b"", base=5, ver=1), "'base'"),
        (_delta_with_body(b"\x80"), "truncated varint"),
        (_delta_with_body(encode_varints(np.array([10**6]))), "cell count"),
        (
            _delta_with_body(_cell([4, 10, 10, _h(50, 0, 0), _h(50, 1, 0), _h(-50, 0, 0)])),
            "truncated",
        ),
        (_delta_with_body(_cell([2, 10, 10, _h(50, 0, 0), 0])), "vertex count"),
        (
            _delta_with_body(_cell([4, 10, 10, _h(50, 0, 3), _h(50, 1, 0), _h(-50, 0, 0), 0])),
            "unknown vector type",
        ),
        (
            _delta_with_body(_cell([4, 10, 10, _h(50, 3, 0), _h(50, 1, 0), _h(-50, 0, 0), 0])),
            "mode",
        ),
        (
            _delta_with_body(_cell([4, 190, 10, _h(50, 0, 0), _h(50, 1, 0), _h(-50, 0, 0), 0])),
            "outside the cell",
        ),
        # clockwise square: free space would be on the right
        (
            _delta_with_body(_cell([4, 10, 10, _h(50, 1, 0), _h(50, 0, 0), _h(-50, 1, 0), 0])),
            "clockwise",
        ),
        # bow tie: the ring crosses itself
        (
            _delta_with_body(
                _cell([4, 10, 10, _h(50, 2, 0), _h(-50, 0, 0), _h(70, 2, 0), _z(50), _z(-50), 0])
            ),
            "not simple",
        ),
        # open ring: the last vertex is the first one again (zero-length closing vector)
        (
            _delta_with_body(
                _cell([4, 10, 10, _h(50, 0, 0), _h(50, 1, 0), _h(-50, 2, 0), _z(-50), 0])
            ),
            "zero-length",
        ),
        (_delta_with_body(_cell(GOOD_RING) + b"\x01"), "trailing"),
    ],
)
def test_malformed_messages_are_rejected_with_one_error(msg, match):
    with pytest.raises(DecodeError, match=match):
        decode_delta(msg)


def test_a_good_hand_made_delta_decodes():
    delta = decode_delta(_delta_with_body(_cell(GOOD_RING)))
    assert delta.cells[0].area == pytest.approx(0.25)


def test_decoding_never_touches_an_existing_map():
    pmap = sample_map()
    before = {k: c for k, c in pmap.cells.items()}
    with pytest.raises(DecodeError):
        pmap.apply_delta(decode_delta(b"garbage"))
    assert dict(pmap.cells) == before


def test_golden_correction_vector_replays_to_its_cells():
    """A receiver that replayed the golden keyframe merges follows the golden correction
    to the cells its description lists (the atlas from the merges alone)."""
    from polyswarm.slam.follow import Atlas, replay_correction
    from protocols.golden.make_golden import golden_correction
    from protocols.mapcodec import decode_correction, encode_correction

    before, _, ops, fix, _ = golden_correction()
    assert encode_correction(fix) == (GOLDEN / "correct_v1.bin").read_bytes()
    assert encode_merge(ops[1]) == (GOLDEN / "merge_keyframe_v1.bin").read_bytes()
    pmap, atlas = GridPolyMap(2.0), Atlas()
    for k, op in enumerate(ops):
        raw = (GOLDEN / "merge_keyframe_v1.bin").read_bytes() if k == 1 else encode_merge(op)
        got = decode_merge(raw)
        assert got.keyframe == k
        pmap = pmap.replay(got).map
        atlas.add(got.keyframe, got.polygon, got.options)
    assert pmap.version == before.version
    c = json.loads((GOLDEN / "correct_v1.json").read_text())
    back = decode_correction((GOLDEN / "correct_v1.bin").read_bytes())
    assert [[k, list(d)] for k, d in back.moves] == c["moves"] and back.digest == c["digest"]
    after, _, changed = replay_correction(pmap, atlas, back)
    assert after.version == c["version"]
    cells = [
        {"index": list(x.index), "polygons": describe_polygons(x.polygons)}
        for x in sorted(changed, key=lambda x: x.index)
    ]
    assert cells == c["cells"]
