"""tf for the agent's ROS 2 node: ``/tf`` and ``/tf_static`` in, ``map -> odom`` out.

tf2_msgs (the type of ``/tf``) is not among the ROS 2 packages on PyPI, so rclpy cannot
create its publishers or subscriptions. This module speaks it on the robot's DDS domain
directly, with Cyclone DDS's Python binding (``pip install cyclonedds``): the types of
``agents.dds_types`` are tf2_msgs/TFMessage and its parts under the names ROS 2 gives
them in DDS (``tf2_msgs::msg::dds_::TFMessage_`` on the topic ``rt/tf``), in plain CDR,
so Fast DDS and Cyclone DDS nodes of the robot (tf2, RViz, Nav2) read and write them as
their own.

    link = TfLink(domain_id, "tb3_1/tf", "tb3_1/tf_static", on_tf)
    link.publish("map", "odom", (x, y, yaw), stamp_s)   # map -> odom
    link.close()

``on_tf(message, topic)`` gets every TFMessage read, with "/tf" or "/tf_static": its
fields are named as the ROS message's (``transforms[k].header.frame_id``,
``.child_frame_id``, ``.transform.translation.x``, ...), as ``protocols.tf`` reads them.
"""

from __future__ import annotations

import logging
import math
import threading

from polyswarm.errors import ConfigError
from protocols.tf import TF, TF_STATIC

log = logging.getLogger(__name__)

TF_DEPTH = 100  # messages a /tf reader holds: tf2's own listener keeps 100
POLL_S = 0.05  # the reader thread's wait for data, seconds (it also watches for close)


def transform_stamped(parent: str, child: str, pose, stamp_s: float):
    """A geometry_msgs/TransformStamped of ``child`` in ``parent``: (x m, y m, yaw rad)."""
    from agents.dds_types import Header, Quaternion, Transform, TransformStamped, Vector3, time_of

    x, y, yaw = (float(v) for v in pose)
    return TransformStamped(
        Header(time_of(stamp_s), parent),
        child,
        Transform(Vector3(x, y, 0.0), Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))),
    )


def dds_topic(key: str) -> str:
    """A ROS topic name (``tb3_1/tf``, relative to the root) as ROS 2 names it in DDS."""
    return "rt/" + key.strip("/")


class TfLink:
    """A DDS participant on the robot's domain: readers of ``tf_key`` and
    ``tf_static_key`` (their messages to ``on_tf`` from a thread of its own) and a
    writer of ``tf_key``."""

    def __init__(self, domain_id: int, tf_key: str, tf_static_key: str, on_tf) -> None:
        try:
            from cyclonedds.core import Policy, Qos
            from cyclonedds.domain import DomainParticipant
            from cyclonedds.pub import DataWriter
            from cyclonedds.sub import DataReader
            from cyclonedds.topic import Topic

            from agents.dds_types import TFMessage
        except ImportError as e:
            raise ConfigError(
                "tf in the robot's ROS 2 graph needs Cyclone DDS's Python binding: "
                "pip install 'polyswarm[ros2]'"
            ) from e
        self.on_tf = on_tf
        self.participant = DomainParticipant(domain_id)
        cdr1 = Policy.DataRepresentation(use_cdrv0_representation=True)  # ROS 2's plain CDR
        reliable = Policy.Reliability.Reliable(0)
        tf_qos = Qos(reliable, Policy.Durability.Volatile, Policy.History.KeepLast(TF_DEPTH), cdr1)
        # as tf2's static broadcaster: the latest message kept for readers that come later
        static_qos = Qos(
            reliable, Policy.Durability.TransientLocal, Policy.History.KeepLast(1), cdr1
        )
        tf_topic = Topic(self.participant, dds_topic(tf_key), TFMessage)
        static_topic = Topic(self.participant, dds_topic(tf_static_key), TFMessage)
        self.writer = DataWriter(self.participant, tf_topic, qos=tf_qos)
        self._readers = [
            (DataReader(self.participant, tf_topic, qos=tf_qos), TF),
            (DataReader(self.participant, static_topic, qos=static_qos), TF_STATIC),
        ]
        self.published = 0
        self.received = {TF: 0, TF_STATIC: 0}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name="ros2-tf", daemon=True)
        self._thread.start()

    def publish(self, parent: str, child: str, pose, stamp_s: float) -> None:
        """``child`` in ``parent`` (x m, y m, yaw rad) on ``/tf``, stamped ``stamp_s``."""
        from agents.dds_types import TFMessage

        self.writer.write(TFMessage([transform_stamped(parent, child, pose, stamp_s)]))
        self.published += 1

    def _read(self) -> None:
        while not self._stop.wait(POLL_S):
            for reader, topic in self._readers:
                for msg in reader.take(N=TF_DEPTH):
                    if not hasattr(msg, "transforms"):  # a writer gone, not data
                        continue
                    self.received[topic] += 1
                    try:
                        self.on_tf(msg, topic)
                    except Exception:  # a bad message must not end the reader
                        log.warning("tf: a message on %s was not used", topic, exc_info=True)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.participant = self.writer = self._readers = None
