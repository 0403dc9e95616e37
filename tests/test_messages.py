"""Protocol messages: round trips, malformed input and map chunking (protocols/messages.py)."""

from __future__ import annotations

import dataclasses
import math

import msgpack
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from polyswarm.errors import ConfigError, DecodeError
from protocols.chunks import CHUNK_BYTES, MapChunk, MapKind, Reassembler, chunk_payload
from protocols.golden.make_golden import golden_messages
from protocols.keys import SwarmKeys
from protocols.messages import (
    ENVELOPE_KEYS,
    TYPES,
    Assignment,
    AssignmentKind,
    Clock,
    CoordinatorStatus,
    Odometry,
    Pose,
    ProtocolError,
    RobotState,
    RobotStatus,
    Scan,
    decode,
    encode,
)

# one message of every type, as in the golden vectors (the scan, holding an array, has
# its own round-trip test)
SAMPLES = [m for name, m in golden_messages() if name != "scan"]


@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: m.TYPE)
def test_round_trip_keeps_every_field_and_the_envelope(msg):
    env, back = decode(encode(msg, "r1", 42, 123.5))
    assert (env.type, env.sender, env.seq, env.stamp_s) == (msg.TYPE, "r1", 42, 123.5)
    assert back == msg


def test_coordinator_status_without_the_optional_cpu_ms_decodes_with_zero():
    status = dict(golden_messages())["coordinator-status"]
    raw = msgpack.unpackb(encode(status, "coordinator", 3, 1.0))
    assert raw.pop("cpu_ms") == status.cycle_cpu_ms > 0
    _, back = decode(msgpack.packb(raw), CoordinatorStatus)
    assert back.cycle_cpu_ms == 0.0 and back.cycle_ms == status.cycle_ms


def test_coordinator_status_carries_its_loss_counts_and_refuses_bad_ones():
    status = dataclasses.replace(
        dict(golden_messages())["coordinator-status"], gaps=3, fetches=2, fetch_bytes=4096
    )
    _, back = decode(encode(status, "coordinator", 3, 1.0), CoordinatorStatus)
    assert (back.gaps, back.fetches, back.fetch_bytes) == (3, 2, 4096)
    for bad in ([1, 2], [1, -2, 3], "3"):
        raw = msgpack.unpackb(encode(status, "coordinator", 3, 1.0))
        raw["losses"] = bad
        with pytest.raises(DecodeError):
            decode(msgpack.packb(raw), CoordinatorStatus)


def test_scan_round_trip_keeps_inf_and_nan_beams():
    r = np.array([1.0, np.inf, np.nan, 29.5], dtype=np.float32)
    _, back = decode(encode(Scan(-2.35, 0.0065, 0.1, 30.0, r), "sim", 0, 0.0), Scan)
    assert back.ranges_m[0] == pytest.approx(1.0)
    assert math.isinf(back.ranges_m[1]) and math.isnan(back.ranges_m[2])
    assert back.angle_min_rad == -2.35


def test_every_type_is_registered_and_bodies_never_reuse_envelope_keys():
    for msg in SAMPLES:
        assert TYPES[msg.TYPE] is type(msg)
        assert not ENVELOPE_KEYS & msg.body().keys()


def _mutated(msg, **changes) -> bytes:
    obj = msgpack.unpackb(encode(msg, "r1", 0, 0.0))
    obj.update(changes)
    return msgpack.packb({k: v for k, v in obj.items() if v is not ...}, use_bin_type=True)


@pytest.mark.parametrize(
    "data, why",
    [
        (b"", "empty"),
        (b"\xc1", "not msgpack"),
        (msgpack.packb([1, 2]), "not a map"),
        (_mutated(Clock(1.0), t="teleport"), "unknown type"),
        (_mutated(Clock(1.0), v=99), "protocol version"),
        (_mutated(Clock(1.0), src="r1/../x"), "bad sender"),
        (_mutated(Clock(1.0), seq=-1), "negative seq"),
        (_mutated(Clock(1.0), time="soon"), "string for a number"),
        (_mutated(Clock(1.0), time=float("nan")), "NaN time"),
        (_mutated(Odometry(0, 0, 0), x=...), "missing field"),
        (_mutated(Pose(0, 0, 0), wait="not a name!"), "bad robot name"),
        (_mutated(RobotStatus(RobotState.IDLE), state="dancing"), "unknown enum"),
        (_mutated(Assignment(AssignmentKind.STOP, -1), goal=[1.0]), "short point"),
        (_mutated(Scan(0, 0.1, 0.1, 30, np.ones(4)), r=b"\x00" * 7), "ragged ranges"),
        (_mutated(Scan(0, 0.1, 0.1, 30, np.ones(4)), rmax=0.05), "rmax below rmin"),
        (_mutated(MapChunk(MapKind.MAP, -1, 1, 1, 0, 1, 3, b"abc"), part=1), "part >= parts"),
        (_mutated(MapChunk(MapKind.MAP, -1, 1, 1, 0, 1, 3, b"abc"), base=5), "base after ver"),
        (b"\x00" * (CHUNK_BYTES + 5000), "too large"),
    ],
)
def test_malformed_messages_raise_the_one_protocol_error(data, why):
    with pytest.raises(ProtocolError):
        decode(data)


def test_protocol_error_is_the_projects_decode_error():
    assert issubclass(ProtocolError, DecodeError)


def test_decode_refuses_a_type_other_than_expected():
    with pytest.raises(ProtocolError, match="expected"):
        decode(encode(Clock(1.0), "sim", 0, 0.0), Odometry)


def _decode_or_none(data: bytes):
    """Decoded message, or None for ProtocolError; any other exception fails the test."""
    try:
        return decode(data)
    except ProtocolError:
        return None


def _stable(got) -> None:
    """What was accepted is a valid message: it re-encodes to the same message."""
    if got is not None:
        env, msg = got
        env2, msg2 = decode(encode(msg, env.sender, env.seq, env.stamp_s))
        assert env2 == env
        assert msg2.body().keys() == msg.body().keys()


@given(st.binary(max_size=300))
def test_random_bytes_never_raise_anything_but_protocol_error(data):
    _stable(_decode_or_none(data))


@given(st.sampled_from(SAMPLES), st.data())
def test_mutated_valid_messages_decode_or_raise_protocol_error(msg, data):
    raw = bytearray(encode(msg, "r1", 3, 1.0))
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(raw) - 1))
        raw[i] = data.draw(st.integers(0, 255))
    _stable(_decode_or_none(bytes(raw)))


# --- chunking ------------------------------------------------------------------------------


@pytest.mark.parametrize("size", [0, 1, CHUNK_BYTES, CHUNK_BYTES + 1, 3 * CHUNK_BYTES + 17])
def test_chunks_reassemble_in_any_order_and_stay_under_64_kb(size):
    payload = np.random.default_rng(size).bytes(size)
    chunks = chunk_payload(MapKind.DELTA, payload, 4, 5, stream=1)
    assert len(chunks) == max(1, -(-size // CHUNK_BYTES))
    wire = [encode(c, "r1", k, 0.0) for k, c in enumerate(chunks)]
    assert max(len(w) for w in wire) < 64 * 1024
    asm, done = Reassembler(), None
    for w in reversed(wire):
        _, c = decode(w, MapChunk)
        done = asm.add("r1", c, 0.0) or done
    assert done is not None
    first, whole = done
    assert whole == payload and (first.base, first.ver) == (4, 5)


def test_interleaved_streams_of_two_senders_do_not_mix():
    a, b = b"a" * (2 * CHUNK_BYTES + 5), b"b" * (2 * CHUNK_BYTES + 9)
    ca, cb = chunk_payload(MapKind.MAP, a, -1, 1, 7), chunk_payload(MapKind.MAP, b, -1, 2, 7)
    asm, out = Reassembler(), {}
    for x, y in zip(ca, cb, strict=True):
        for sender, c in (("r1", x), ("r2", y)):
            done = asm.add(sender, c, 0.0)
            if done:
                out[sender] = done[1]
    assert out == {"r1": a, "r2": b}


def test_inconsistent_chunk_is_refused_and_a_stale_stream_expires():
    chunks = chunk_payload(MapKind.MAP, b"x" * (CHUNK_BYTES + 10), -1, 1, 1)
    asm = Reassembler(timeout_s=5.0)
    assert asm.add("r1", chunks[0], 0.0) is None
    bad = MapChunk(MapKind.MAP, -1, 2, 1, 1, 2, CHUNK_BYTES + 10, b"x" * 10)  # other version
    with pytest.raises(ProtocolError):
        asm.add("r1", bad, 1.0)
    assert asm.add("r1", chunks[0], 2.0) is None
    assert asm.add("r1", chunks[1], 100.0) is None  # the first part expired meanwhile


# --- keys ----------------------------------------------------------------------------------


def test_keys_are_under_the_swarm_and_names_are_checked():
    k = SwarmKeys("lab")
    assert k.robot("r1").map_delta == "polyswarm/lab/robots/r1/map/delta"
    assert k.robot_of(k.robot("r7").pose) == "r7"
    assert k.robot_of("polyswarm/other/robots/r7/pose") is None
    assert k.assignment("r2") == "polyswarm/lab/coordinator/assignment/r2"
    assert k.alive_name(k.alive("agent", "r3")) == ("agent", "r3")
    for bad in ("", "a/b", "x*", "r 1", "a" * 33):
        with pytest.raises(ConfigError):
            k.robot(bad)


# --- golden vectors ------------------------------------------------------------------------


def test_golden_messages_decode_and_the_encoder_reproduces_them():
    import json
    from pathlib import Path

    from protocols.golden.make_golden import golden_messages

    golden = json.loads(
        (Path(__file__).resolve().parents[1] / "protocols/golden/messages_v1.json").read_text()
    )
    msgs = dict(golden_messages())
    assert set(golden) == set(msgs) == {m.TYPE for m in msgs.values()}
    for name, g in golden.items():
        env, msg = decode(bytes.fromhex(g["hex"]))
        assert (env.type, env.sender, env.seq, env.stamp_s) == (name, "r1", 7, 12.5)
        body = {k: (v.hex() if isinstance(v, bytes) else v) for k, v in msg.body().items()}
        assert json.loads(json.dumps(body)) == g["body"]
        assert encode(msgs[name], "r1", 7, 12.5).hex() == g["hex"]


def test_a_pose_names_its_frame_only_once_anchored():
    from protocols.messages import Anchor, Pose

    plain = Pose(1.0, 2.0, 0.5, 3)
    assert "frame" not in plain.body()  # as older senders wrote it
    _, back = decode(encode(Pose(1.0, 2.0, 0.5, 3, "", 2), "r1", 0, 0.0), Pose)
    assert back.frame == 2
    _, a = decode(encode(Anchor(1, 3.0, -4.0, 1.5), "coordinator", 0, 0.0), Anchor)
    assert (a.frame, a.x, a.y, a.theta) == (1, 3.0, -4.0, 1.5)
    with pytest.raises(ProtocolError):  # anchors count from 1
        decode(encode(Anchor(0, 3.0, -4.0, 1.5), "coordinator", 0, 0.0), Anchor)
    with pytest.raises(ProtocolError):  # not in the same building
        decode(encode(Anchor(1, 3.0e6, -4.0, 1.5), "coordinator", 0, 0.0), Anchor)
    assert "own" not in Anchor(1, 3.0, -4.0, 1.5).body()  # as older senders wrote it
    assert "own" not in plain.body()
    _, p = decode(encode(Pose(1.0, 2.0, 0.5, 3, "", 2, own=True), "r1", 0, 0.0), Pose)
    assert p.own and p.frame == 2
    _, w = decode(encode(Anchor(2, 0.0, 0.0, 0.0, own=True), "coordinator", 0, 0.0), Anchor)
    assert w.own and w.frame == 2
    with pytest.raises(ProtocolError):  # a withdrawal moves nothing
        decode(encode(Anchor(2, 1.0, 0.0, 0.0, own=True), "coordinator", 0, 0.0), Anchor)
    _, t = decode(encode(Anchor(3, 2.0, -1.0, 0.5, team=True), "coordinator", 0, 0.0), Anchor)
    assert t.team and not t.own and (t.frame, t.x, t.y, t.theta) == (3, 2.0, -1.0, 0.5)
    assert "team" not in Anchor(1, 3.0, -4.0, 1.5).body()  # as older senders wrote it
    with pytest.raises(ProtocolError):  # a withdrawal joins no team
        decode(encode(Anchor(2, 0.0, 0.0, 0.0, True, True), "coordinator", 0, 0.0), Anchor)


def test_priors_travel_whole_and_bad_ones_are_refused():
    from protocols.frame_messages import MAX_PRIORS, Priors

    good = Priors(2, 0.05, 0.01, ((3, 1250, -400, 1745), (6, 1300, -410, -1800)))
    _, back = decode(encode(good, "coordinator", 0, 0.0), Priors)
    assert back == good
    bad = [
        Priors(2, 0.05, 0.01, ((6, 0, 0, 0), (3, 0, 0, 0))),  # ids must ascend
        Priors(2, 0.05, 0.01, ((3, 0, 0, 0), (3, 0, 0, 0))),  # ... strictly
        Priors(2, 0.05, 0.01, ((-1, 0, 0, 0),)),
        Priors(2, 0.05, 0.01, ((1, 10**9, 0, 0),)),  # 1,000 km: not the same building
        Priors(2, 0.05, 0.01, ((1, 0, 0, 500_000),)),  # 5 rad: not wrapped
        Priors(2, 0.0, 0.01, ((1, 0, 0, 0),)),  # no standard deviation
        Priors(-1, 0.05, 0.01, ((1, 0, 0, 0),)),
        Priors(0, 0.05, 0.01, tuple((k, 0, 0, 0) for k in range(MAX_PRIORS + 1))),
    ]
    for msg in bad:
        with pytest.raises(ProtocolError):
            decode(encode(msg, "coordinator", 0, 0.0), Priors)
    body = good.body() | {"p": [[3, 1.5, 0, 0]]}  # a float where millimetres go
    with pytest.raises(ProtocolError):
        Priors.from_body(body)


def test_a_poses_clear_profile_travels_whole_or_is_refused():
    from polyswarm.frames.sighting import SECTORS
    from protocols.messages import Pose

    prof = bytes(range(SECTORS))
    _, back = decode(encode(Pose(1.0, 2.0, 0.5, 3, clear=prof), "r1", 0, 0.0), Pose)
    assert back.clear == prof
    assert "clr" not in Pose(1.0, 2.0, 0.5, 3).body()  # not sent: absent
    for bad in (prof[:-1], prof + b"\0", "text"):
        body = {**Pose(1.0, 2.0, 0.5, 3).body(), "clr": bad}
        with pytest.raises(ProtocolError, match="clr"):
            Pose.from_body(body)


def test_a_status_with_a_target_the_robot_chose_itself_is_valid():
    """Out of every coordinator's reach a robot works on targets numbered from -2 down
    (agents.alone): its status is a valid message, not a malformed one."""
    from protocols.messages import RobotState, RobotStatus, decode, encode

    status = RobotStatus(RobotState.NAVIGATING, -7, keyframes=3)
    _, back = decode(encode(status, "r1", 0, 1.0), RobotStatus)
    assert back.target == -7
