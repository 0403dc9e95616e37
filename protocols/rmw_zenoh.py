"""ROS 2 on Zenoh without a bridge: rmw_zenoh's key expressions, liveliness tokens and
attachments, so that an agent talks to a robot whose ROS 2 runs on rmw_zenoh.

As specified in rmw_zenoh's design document (``docs/design.md`` of ros2/rmw_zenoh,
the version of commit 99a6a2bd, checked by ``tests/test_rmw_zenoh.py``):

* data:  ``<domain_id>/<fully qualified name>/<DDS type name>/<type hash>``, e.g.
  ``0/robot1/chatter/std_msgs::msg::dds_::String_/RIHS01_df66...``; the payload is the
  CDR message, as zenoh-bridge-ros2dds carries it;
* liveliness: ``@ros2_lv/<domain_id>/<session id>/<node id>/<entity id>/<kind>/
  <mangled enclave>/<mangled namespace>/<node name>[/<mangled qualified name>/<type>/
  <hash>/<qos>]``, a mangled name having each ``/`` replaced by ``%`` (``%`` alone when
  empty), kinds NN (node), MP (publisher), MS (subscription);
* attachment of every publication: sequence number (int64, little-endian), source
  timestamp (int64 ns since the UNIX epoch, little-endian), the GID's length (one byte,
  16) and the publisher's 16-byte GID.

Type hashes (REP-2016, ``RIHS01_...``) come from ``rosbags``' type store of ROS 2 Jazzy,
the first distribution rmw_zenoh is a tier-1 middleware of.
"""

from __future__ import annotations

import functools
import struct

from protocols.messages import ProtocolError

LIVELINESS_PREFIX = "@ros2_lv"
GID_BYTES = 16
ATTACHMENT = struct.Struct("<qqB")  # sequence number, timestamp (ns), GID length
DEFAULT_QOS_DEPTH = 10


@functools.cache
def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def dds_type_name(ros_type: str) -> str:
    """``sensor_msgs/msg/LaserScan`` -> ``sensor_msgs::msg::dds_::LaserScan_``."""
    pkg, kind, name = ros_type.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def type_hash(ros_type: str) -> str:
    """The REP-2016 type hash (``RIHS01_`` and 64 hex digits)."""
    return _typestore().hash_rihs01(ros_type)


def mangle(name: str) -> str:
    """A name with each ``/`` replaced by ``%``; ``%`` alone for an empty name."""
    return name.replace("/", "%") if name.strip("/") else "%"


def _namespace(namespace: str) -> str:
    """A namespace as its token chunk: ``tb3_1`` or ``/tb3_1`` -> ``%tb3_1``, none -> ``%``."""
    ns = namespace.strip("/")
    return mangle("/" + ns) if ns else "%"


def qualified_name(namespace: str, name: str) -> str:
    """The fully qualified topic name: ``/ns/name`` (``/name`` without namespace)."""
    parts = [p for p in (namespace.strip("/"), name.strip("/")) if p]
    return "/" + "/".join(parts)


def topic_key(domain_id: int, fq_name: str, ros_type: str, hash_: str | None = None) -> str:
    """The data key of a topic; ``hash_="*"`` matches any type hash (a subscription that
    accepts publishers built without type hashes, such as Humble's)."""
    h = type_hash(ros_type) if hash_ is None else hash_
    return f"{domain_id}/{fq_name.strip('/')}/{dds_type_name(ros_type)}/{h}"


def qos_keyexpr(depth: int = DEFAULT_QOS_DEPTH) -> str:
    """QoS in the token's compact form: every policy at its default but the history
    depth (``<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan
    s>,<ns>:<liveliness>,<s>,<ns>``, defaults left empty)."""
    return f"::,{depth}:,:,:,,"


def node_token(domain_id: int, session_id: str, node_id: int, namespace: str, node: str) -> str:
    return "/".join(
        [
            LIVELINESS_PREFIX,
            str(domain_id),
            session_id,
            str(node_id),
            str(node_id),  # a node's entity id is its node id
            "NN",
            "%",
            _namespace(namespace),
            node,
        ]
    )


def entity_token(
    domain_id: int,
    session_id: str,
    node_id: int,
    entity_id: int,
    kind: str,
    namespace: str,
    node: str,
    fq_name: str,
    ros_type: str,
    hash_: str | None = None,
    qos: str | None = None,
) -> str:
    """The liveliness token of a publisher (``kind`` "MP") or subscription ("MS")."""
    if kind not in ("MP", "MS", "SS", "SC"):
        raise ValueError(f"unknown entity kind {kind!r}")
    return "/".join(
        [
            LIVELINESS_PREFIX,
            str(domain_id),
            session_id,
            str(node_id),
            str(entity_id),
            kind,
            "%",
            _namespace(namespace),
            node,
            mangle(fq_name),
            dds_type_name(ros_type),
            type_hash(ros_type) if hash_ is None else hash_,
            qos_keyexpr() if qos is None else qos,
        ]
    )


def encode_attachment(seq: int, stamp_ns: int, gid: bytes) -> bytes:
    if len(gid) != GID_BYTES:
        raise ValueError(f"a GID has {GID_BYTES} bytes, got {len(gid)}")
    return ATTACHMENT.pack(seq, stamp_ns, GID_BYTES) + bytes(gid)


def decode_attachment(data: bytes) -> tuple[int, int, bytes]:
    """(sequence number, source timestamp in ns, publisher GID); ProtocolError when the
    bytes are not an rmw_zenoh attachment."""
    if data is None or len(data) != ATTACHMENT.size + GID_BYTES:
        raise ProtocolError(f"rmw_zenoh attachment of {0 if data is None else len(data)} bytes")
    seq, stamp, n = ATTACHMENT.unpack_from(data)
    if n != GID_BYTES:
        raise ProtocolError(f"rmw_zenoh attachment with a GID of {n} bytes")
    return seq, stamp, bytes(data[ATTACHMENT.size :])
