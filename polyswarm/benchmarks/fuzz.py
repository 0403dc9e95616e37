"""``polyswarm fuzz``: mutation fuzzing of every decoder of outside bytes.

Valid seeds (golden vectors and freshly encoded messages) are mutated (byte flips,
truncations, insertions, duplicated spans) and fed to their decoder; anything but the
decoder's own error type is a crash. Deterministic for a seed.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from pathlib import Path

import numpy as np

from polyswarm.errors import DecodeError


def _mutate(rng: random.Random, data: bytes) -> bytes:
    b = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        op = rng.randrange(5)
        if not b:
            b.append(rng.randrange(256))
            continue
        i = rng.randrange(len(b))
        if op == 0:
            b[i] = rng.randrange(256)
        elif op == 1:
            b[i] ^= 1 << rng.randrange(8)
        elif op == 2:
            del b[i:]
        elif op == 3:
            b[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        else:
            j = min(len(b), i + rng.randint(1, 16))
            b[i:i] = b[i:j]
    return bytes(b)


def decoders() -> dict[str, tuple[Callable[[bytes], object], list[bytes]]]:
    """Decoder and valid seeds per kind of outside data."""
    from polyswarm.slam.scan import LaserScan
    from protocols import rmw_zenoh, ros
    from protocols.golden.make_golden import golden_maps, golden_messages
    from protocols.mapcodec import (
        decode_any_map,
        decode_correction,
        decode_delta,
        decode_map,
        decode_merge,
        encode_cells_map,
    )
    from protocols.messages import decode, encode

    golden = Path(__file__).resolve().parents[2] / "protocols" / "golden"
    scan = LaserScan(np.linspace(0.5, 5.0, 32), -1.5, 0.1, 0.1, 30.0, 3.25)
    return {
        "message": (decode, [encode(m, "r1", 7, 12.5) for _, m in golden_messages()]),
        "map": (decode_map, [(golden / "map_v1.bin").read_bytes()]),
        "delta": (decode_delta, [(golden / "delta_v1.bin").read_bytes()]),
        "merge": (
            decode_merge,
            [(golden / n).read_bytes() for n in ("merge_v1.bin", "merge_keyframe_v1.bin")],
        ),
        "correction": (
            decode_correction,
            [(golden / "correct_v1.bin").read_bytes(), _long_correction()],
        ),
        "whole map as cells": (decode_any_map, [encode_cells_map(golden_maps()[1])]),
        "ros-laserscan": (ros.decode_laserscan, [ros.encode_laserscan(scan)]),
        "ros-odometry": (ros.decode_odometry, [ros.encode_odometry(1.0, (1.0, 2.0, 0.5))]),
        "ros-twist": (ros.decode_twist, [ros.encode_twist(0.2, -0.4)]),
        "ros-tf": (ros.decode_tf, [_tf_seed()]),
        "rmw_zenoh-attachment": (
            rmw_zenoh.decode_attachment,
            [rmw_zenoh.encode_attachment(3, 1_700_000_000_000_000_000, bytes(range(16)))],
        ),
    }


def _long_correction() -> bytes:
    """A correction long enough to go compressed ("bz")."""
    from polyswarm.slam.follow import CorrectionOp
    from protocols.mapcodec import encode_correction

    moves = tuple((k, (30 + k % 5, -12, 90)) for k in range(0, 120, 3))
    return encode_correction(CorrectionOp(2.0, 3, 4, moves, 99))


def _tf_seed() -> bytes:
    from protocols import ros

    ts = ros.typestore()
    T = ts.types
    tr = T["geometry_msgs/msg/TransformStamped"](
        header=T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="base_link"
        ),
        child_frame_id="laser",
        transform=T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](x=0.1, y=0.0, z=0.2),
            rotation=T["geometry_msgs/msg/Quaternion"](x=1.0, y=0.0, z=0.0, w=0.0),
        ),
    )
    return bytes(ts.serialize_cdr(T[ros.TF_MESSAGE](transforms=[tr]), ros.TF_MESSAGE))


def run(count: int, seed: int = 0, progress=None) -> dict:
    """``count`` mutated inputs per decoder; crashes (unexpected exceptions) listed."""
    out = {}
    for name, (decode, seeds) in decoders().items():
        rng = random.Random(f"{seed}-{name}")
        accepted = rejected = 0
        crashes: list[str] = []
        for k in range(count):
            data = _mutate(rng, seeds[k % len(seeds)])
            try:
                decode(data)
                accepted += 1
            except DecodeError:
                rejected += 1
            except Exception as e:  # a crash: the decoder let something else escape
                if len(crashes) < 10:
                    crashes.append(f"{type(e).__name__}: {e} (input {data[:64].hex()})")
            if progress and k % 1000 == 0:
                progress(name, k, count)
        out[name] = {
            "inputs": count,
            "accepted": accepted,
            "rejected": rejected,
            "crashes": count - accepted - rejected,
            "examples": crashes,
        }
    return out
