"""A ROS 2 action client on DDS, for actions whose types are not on PyPI (Nav2's
``navigate_to_pose``): Cyclone DDS's Python binding speaks the action's protocol with
the types of ``agents.dds_types``.

A ROS 2 action ``<name>`` is services and topics under ``<name>/_action/``: the
``send_goal`` and ``cancel_goal`` services (DDS topics ``rq/<name>/_action/send_goalRequest``
and ``rr/<name>/_action/send_goalReply``, ...) and the ``feedback`` and ``status`` topics.
A service's replies carry no goal id and reach every client's reader, so this client
follows its goals on ``status``, where the server lists every goal by its id (accepted,
executing, canceling; then succeeded, canceled or aborted), and takes a ``send_goal``
reply as its own only while one is awaited (a rejection shows nowhere else).

    client = ActionClient(participant, "tb4_1/navigate_to_pose", NAVIGATE_TO_POSE)
    gid = client.send(NavigateToPoseGoal(...))
    client.poll(); client.state(gid), client.feedback.get(gid)
    client.cancel(gid)
"""

from __future__ import annotations

import logging
import math
import os
import time
from dataclasses import dataclass
from enum import StrEnum

from polyswarm.errors import ConfigError

log = logging.getLogger(__name__)

TAKE_MAX = 64  # samples taken from a reader per poll


class GoalState(StrEnum):
    SENT = "sent"  # no word from the server yet
    ACTIVE = "active"  # accepted, executing or canceling
    SUCCEEDED = "succeeded"
    CANCELED = "canceled"
    ABORTED = "aborted"
    REJECTED = "rejected"

    @property
    def done(self) -> bool:
        return self not in (GoalState.SENT, GoalState.ACTIVE)


# action_msgs/msg/GoalStatus: 1 accepted, 2 executing, 3 canceling, 4 succeeded,
# 5 canceled, 6 aborted (0: unknown)
STATUS = {
    1: GoalState.ACTIVE,
    2: GoalState.ACTIVE,
    3: GoalState.ACTIVE,
    4: GoalState.SUCCEEDED,
    5: GoalState.CANCELED,
    6: GoalState.ABORTED,
}


@dataclass(frozen=True)
class ActionTypes:
    """An action's own types (the rest is action_msgs'): IDL struct classes."""

    send_goal_request: type
    send_goal_response: type
    feedback_message: type


def navigate_to_pose() -> ActionTypes:
    from agents import dds_types as t

    return ActionTypes(
        t.NavigateToPoseSendGoalRequest,
        t.NavigateToPoseSendGoalResponse,
        t.NavigateToPoseFeedbackMessage,
    )


class ActionClient:
    """The client end of the action ``name`` (a topic name without the leading slash)."""

    def __init__(self, participant, name: str, types: ActionTypes) -> None:
        from cyclonedds.core import Policy, Qos
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        from agents.dds_types import CancelGoalRequest, CancelGoalResponse, GoalStatusArray

        self.types = types
        base = name.strip("/") + "/_action/"
        cdr = Policy.DataRepresentation(use_cdrv0_representation=True)
        reliable = Policy.Reliability.Reliable(0)
        service = Qos(reliable, Policy.Durability.Volatile, Policy.History.KeepLast(10), cdr)
        latched = Qos(reliable, Policy.Durability.TransientLocal, Policy.History.KeepLast(1), cdr)
        dp = participant

        def topic(prefix: str, what: str, kind: type):
            return Topic(dp, f"{prefix}/{base}{what}", kind)

        t = types
        self._send = DataWriter(dp, topic("rq", "send_goalRequest", t.send_goal_request), service)
        self._sent = DataReader(dp, topic("rr", "send_goalReply", t.send_goal_response), service)
        self._cancel = DataWriter(dp, topic("rq", "cancel_goalRequest", CancelGoalRequest), service)
        self._replies = DataReader(dp, topic("rr", "cancel_goalReply", CancelGoalResponse), service)
        self._feedback = DataReader(dp, topic("rt", "feedback", t.feedback_message), service)
        self._status = DataReader(dp, topic("rt", "status", GoalStatusArray), latched)
        self.goals: dict[bytes, GoalState] = {}
        self.feedback: dict[bytes, object] = {}  # goal id -> its latest feedback
        self._awaiting: list[bytes] = []  # goals sent whose send_goal reply has not come

    def ready(self) -> bool:
        """Is a server there: the goal requests' reader and the status writer matched?"""
        return bool(
            self._send.get_matched_subscriptions() and self._status.get_matched_publications()
        )

    def send(self, goal) -> bytes:
        """Send ``goal`` (the action's Goal struct); its goal id."""
        from agents.dds_types import UUID

        gid = os.urandom(16)
        self._send.write(self.types.send_goal_request(UUID(list(gid)), goal))
        self.goals[gid] = GoalState.SENT
        self._awaiting.append(gid)
        return gid

    def cancel(self, gid: bytes) -> None:
        """Ask the server to cancel goal ``gid`` (its status then says canceled)."""
        from agents.dds_types import UUID, CancelGoalRequest, GoalInfo, time_of

        self._cancel.write(CancelGoalRequest(GoalInfo(UUID(list(gid)), time_of(0.0))))

    def state(self, gid: bytes) -> GoalState | None:
        return self.goals.get(gid)

    def poll(self) -> None:
        """Take what the server said: replies, statuses, feedback."""
        for reply in self._sent.take(N=TAKE_MAX):  # in the order of the requests
            if not hasattr(reply, "accepted") or not self._awaiting:
                continue
            gid = self._awaiting.pop(0)
            if not reply.accepted:
                self.goals[gid] = GoalState.REJECTED
            elif self.goals.get(gid) == GoalState.SENT:
                self.goals[gid] = GoalState.ACTIVE
        self._replies.take(N=TAKE_MAX)  # to cancels: the status topic says how they went
        for msg in self._status.take(N=TAKE_MAX):
            for st in getattr(msg, "status_list", ()):
                gid = bytes(st.goal_info.goal_id.uuid)
                if gid in self.goals and not self.goals[gid].done and st.status in STATUS:
                    self.goals[gid] = STATUS[st.status]
        for msg in self._feedback.take(N=TAKE_MAX):
            gid = bytes(getattr(getattr(msg, "goal_id", None), "uuid", b""))
            if gid in self.goals:
                self.feedback[gid] = msg.feedback

    def wait_ready(self, timeout_s: float) -> bool:
        """Wait for ``ready`` up to ``timeout_s`` seconds."""
        deadline = time.monotonic() + timeout_s
        while not self.ready():
            if time.monotonic() > deadline:
                return False
            time.sleep(0.05)
        return True


@dataclass(frozen=True)
class Outcome:
    """How a goal sent to Nav2 ended."""

    target: int  # the assignment's target
    state: GoalState
    detail: str


class Nav2Goals:
    """The agent's goals through Nav2's ``navigate_to_pose`` action: one goal at a time,
    the one before canceled; sent once the server is there."""

    def __init__(self, domain_id: int, action_key: str, map_frame: str) -> None:
        try:
            from cyclonedds.domain import DomainParticipant
        except ImportError as e:
            raise ConfigError(
                'agent.output = "nav2" needs Cyclone DDS\'s Python binding: '
                "pip install 'polyswarm[ros2]'"
            ) from e
        self.participant = DomainParticipant(domain_id)
        self.client = ActionClient(self.participant, action_key, navigate_to_pose())
        self.map_frame = map_frame
        self._pending = None  # (target, goal struct) waiting for the server
        self._current: tuple[int, bytes] | None = None  # (target, goal id)
        self.sent = 0

    def navigate(self, target: int, goal_xy, yaw_rad: float, stamp_s: float) -> None:
        """Go to ``goal_xy`` (metres, the map frame), facing ``yaw_rad``; the goal before
        is canceled."""
        from agents.dds_types import (
            Header,
            NavigateToPoseGoal,
            Point,
            Pose,
            PoseStamped,
            Quaternion,
            time_of,
        )

        self.stop()
        q = Quaternion(0.0, 0.0, math.sin(yaw_rad / 2), math.cos(yaw_rad / 2))
        pose = Pose(Point(float(goal_xy[0]), float(goal_xy[1]), 0.0), q)
        goal = NavigateToPoseGoal(PoseStamped(Header(time_of(stamp_s), self.map_frame), pose), "")
        self._pending = (target, goal)
        self._flush()

    def stop(self) -> None:
        """Cancel the goal Nav2 is on, if any."""
        self._pending = None
        if self._current is not None:
            gid = self._current[1]
            if not (self.client.state(gid) or GoalState.SENT).done:
                self.client.cancel(gid)
            self._current = None

    def _flush(self) -> None:
        if self._pending is not None and self.client.ready():
            target, goal = self._pending
            self._current, self._pending = (target, self.client.send(goal)), None
            self.sent += 1
            log.info("goal %d sent to Nav2's navigate_to_pose", target)

    def outcome(self) -> Outcome | None:
        """How the current goal ended, once (None while it runs)."""
        self._flush()
        self.client.poll()
        if self._current is None:
            return None
        target, gid = self._current
        state = self.client.state(gid)
        if state is None or not state.done:
            return None
        self._current = None
        fb = self.client.feedback.get(gid)
        left = f", {fb.distance_remaining:.1f} m from the goal" if fb is not None else ""
        return Outcome(target, state, f"Nav2 {state}{left}")

    def close(self) -> None:
        self.stop()
        self.client = self.participant = None
