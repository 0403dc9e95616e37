"""Regenerate the golden vectors (run only when the format version changes).

    python -m protocols.golden.make_golden

Each ``NAME.bin`` is an encoded message; ``NAME.json`` states what it must decode to,
in integer wire units (10 um), so another implementation can check itself against it.
"""

from __future__ import annotations

import json
from dataclasses import astuple
from pathlib import Path

import numpy as np

from polyswarm.polymap import (
    UNITS_PER_M,
    GridPolyMap,
    MergeOp,
    MergeOptions,
    Ring,
    TypedPolygon,
    VectorType,
    cells_digest,
)
from protocols.mapcodec import encode_correction, encode_delta, encode_map, encode_merge

HERE = Path(__file__).parent
O, F = VectorType.OBSTACLE, VectorType.FRONTIER
SLAM_OPTIONS = MergeOptions(0.05, 0.05, 0.01, 0.1, 0.08)  # the golden merges' options


def golden_maps() -> tuple[GridPolyMap, GridPolyMap]:
    """A 3 m x 1.5 m room with a pillar, then a corridor added to it."""
    room, corridor = _golden_polygons()
    a = GridPolyMap(2.0).merge(room).map
    b = a.merge(corridor).map
    return a, b


def golden_merge() -> tuple[GridPolyMap, MergeOp]:
    """The corridor of ``golden_maps`` sent as a merge into the room, with SLAM's options."""
    a, _ = golden_maps()
    _, corridor = _golden_polygons()
    options = SLAM_OPTIONS
    res = a.merge(corridor, options)
    digest = cells_digest(res.map.cells[i] for i in res.changed)
    return a, MergeOp(2.0, a.version, res.map.version, corridor, options, digest)


def golden_correction():
    """The room and the corridor of ``golden_maps`` merged as keyframes 0 and 1 of a map
    that follows its pose graph; then the corridor moved 2 cm along x, 1 cm back along y
    and turned 5 mrad. Returns (the map and atlas before, the merge ops, the correction,
    the map after)."""
    from polyswarm.slam.follow import Atlas, correct, pose_of

    room, corridor = _golden_polygons()
    options = SLAM_OPTIONS
    pmap, atlas, ops = GridPolyMap(2.0), Atlas(), []
    for kid, poly in enumerate([room, corridor]):
        res = pmap.merge(poly, options)
        digest = cells_digest(res.map.cells[i] for i in res.changed)
        ops.append(MergeOp(2.0, pmap.version, res.map.version, poly, options, digest, kid))
        pmap = res.map
        atlas.add(kid, poly, options)
    before, atlas_before = pmap, atlas.copy()
    poses = {k: pose_of(atlas.poses[k]) for k in (0, 1)}
    poses[1] = poses[1] + np.array([0.02, -0.01, 0.005])
    after, op, _ = correct(pmap, atlas, poses)
    return before, atlas_before, ops, op, after


def _golden_polygons() -> tuple[TypedPolygon, TypedPolygon]:
    """The golden room (with a pillar) and the corridor beside it."""
    room = TypedPolygon(
        Ring([(0.5, 0.5), (3.5, 0.5), (3.5, 2.0), (0.5, 2.0)], [O, F, O, O]),
        (Ring([(1.0, 1.0), (1.0, 1.2), (1.3, 1.2), (1.3, 1.0)], [O] * 4),),
    )
    corridor = TypedPolygon(Ring([(3.4, 1.0), (6.0, 1.0), (6.0, 1.6), (3.4, 1.6)], [O, F, O, F]))
    return room, corridor


def units(xy: np.ndarray) -> list[list[int]]:
    return np.rint(np.asarray(xy) * UNITS_PER_M).astype(np.int64).tolist()


def describe_polygons(polys) -> list:
    return [[{"xy": units(r.xy), "types": r.types.tolist()} for r in p.rings()] for p in polys]


def golden_messages() -> list[tuple[str, object]]:
    """One message of every type (sender "r1", seq 7, stamp 12.5 s)."""
    from protocols.chunks import MapChunk, MapKind
    from protocols.messages import (
        Anchor,
        Assignment,
        AssignmentKind,
        Clock,
        CmdVel,
        CoordinatorStatus,
        MissionState,
        Odometry,
        Pose,
        Priors,
        RobotState,
        RobotStatus,
        Scan,
        Truth,
    )

    return [
        ("scan", Scan(-2.25, 0.5, 0.1, 30.0, np.array([1.0, 2.5, np.inf], dtype=np.float32))),
        ("odom", Odometry(1.5, -2.0, 0.25, 0.5, -0.125)),
        ("cmd_vel", CmdVel(0.25, 0.5, 41)),
        ("pose", Pose(3.0, 4.0, -1.0, 9, "r2")),
        ("robot-status", RobotStatus(RobotState.NAVIGATING, 4, "", 12, 9, 4096, 3.5)),
        (
            "assignment",
            Assignment(AssignmentKind.EXPLORE, 5, (1.0, 2.0), ((0.0, 0.0), (1.0, 0.0)), 4.5, 11),
        ),
        ("anchor", Anchor(1, 12.5, -3.25, 2.0)),
        ("priors", Priors(2, 0.05, 0.0087, ((3, 1250, -400, 1745), (6, 1300, -410, -1800)))),
        (
            "coordinator-status",
            CoordinatorStatus(MissionState.EXPLORING, ("r1", "r2"), 3, 11, 42.0, 12.5, 1000, 9.25),
        ),
        ("clock", Clock(12.5, 9.75)),
        ("truth", Truth({"r1": (1.0, 2.0, 0.5)}, 0, 0)),
        ("map-chunk", MapChunk(MapKind.DELTA, 3, 4, 1, 0, 1, 3, b"abc")),
    ]


def main() -> None:
    from protocols.messages import encode

    out = {}
    for name, msg in golden_messages():
        body = {k: (v.hex() if isinstance(v, bytes) else v) for k, v in msg.body().items()}
        out[name] = {"hex": encode(msg, "r1", 7, 12.5).hex(), "body": body}
    (HERE / "messages_v1.json").write_text(json.dumps(out, indent=1))
    a, b = golden_maps()
    _write(
        "map_v1",
        encode_map(b),
        "polymap",
        version=b.version,
        polygons=describe_polygons(b.dissolve()),
    )
    delta = b.delta_since(a.version)
    cells = [
        {"index": list(c.index), "version": c.version, "polygons": describe_polygons(c.polygons)}
        for c in sorted(delta.cells, key=lambda c: c.index)
    ]
    _write(
        "delta_v1",
        encode_delta(delta),
        "polymap-delta",
        base_version=delta.base_version,
        version=delta.version,
        cells=cells,
    )
    _, op = golden_merge()
    _write(
        "merge_v1",
        encode_merge(op),
        "polymap-merge",
        base_version=op.base_version,
        version=op.version,
        digest=op.digest,
        options_units=[round(v * UNITS_PER_M) for v in astuple(op.options)],
        polygon=describe_polygons([op.polygon])[0],
    )
    _, _, ops, fix, after = golden_correction()
    _write("merge_keyframe_v1", encode_merge(ops[1]), "polymap-merge", keyframe=ops[1].keyframe)
    changed = [c for c in after.cells.values() if c.version == fix.version]
    _write(
        "correct_v1",
        encode_correction(fix),
        "polymap-correct",
        base_version=fix.base_version,
        version=fix.version,
        digest=fix.digest,
        moves=[[k, list(d)] for k, d in fix.moves],
        cells=[
            {"index": list(c.index), "polygons": describe_polygons(c.polygons)}
            for c in sorted(changed, key=lambda c: c.index)
        ],
    )


def _write(name: str, data: bytes, kind: str, **fields) -> None:
    """``NAME.bin`` and ``NAME.json``: what the message must decode to (2 m cells)."""
    (HERE / f"{name}.bin").write_bytes(data)
    head = {"type": kind, "format_version": 1, "cell_size_units": 200000}
    (HERE / f"{name}.json").write_text(json.dumps({**head, **fields}, indent=1))


if __name__ == "__main__":
    main()
