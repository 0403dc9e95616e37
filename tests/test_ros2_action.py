"""The DDS action client (``agents.ros2_action``) against a real ROS 2 action server:
rclpy with Fast DDS (ROS 2 Jazzy from PyPI) serving test_msgs/action/Fibonacci. What
carries Nav2's navigate_to_pose is the same protocol with other goal types."""

from __future__ import annotations

import math
import random
import threading
import time

import pytest
import rclpy
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor

from agents.ros2_action import ActionClient, ActionTypes, GoalState

pytest.importorskip("cyclonedds")
Fibonacci = pytest.importorskip("test_msgs.action").Fibonacci

ABORT_ORDER = 13  # the server aborts this goal half way
STEP_S = 0.05  # the server's time per number


def _execute(handle):
    order, seq = handle.request.order, [0, 1]
    for k in range(order):
        if handle.is_cancel_requested:
            handle.canceled()
            return Fibonacci.Result(sequence=seq)
        if order == ABORT_ORDER and k == order // 2:
            handle.abort()
            return Fibonacci.Result(sequence=seq)
        seq.append(seq[-1] + seq[-2])
        handle.publish_feedback(Fibonacci.Feedback(sequence=seq))
        time.sleep(STEP_S)
    handle.succeed()
    return Fibonacci.Result(sequence=seq)


@pytest.fixture
def fibonacci_server():
    """A real rclpy action server on a DDS domain of the test's own; its domain id."""
    domain = random.randint(1, 200)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node("fibonacci_server", namespace="/robot", context=ctx)
    server = ActionServer(
        node,
        Fibonacci,
        "fibonacci",
        _execute,
        goal_callback=lambda g: GoalResponse.REJECT if g.order < 0 else GoalResponse.ACCEPT,
        cancel_callback=lambda h: CancelResponse.ACCEPT,
        callback_group=ReentrantCallbackGroup(),
    )
    executor = MultiThreadedExecutor(num_threads=4, context=ctx)
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    try:
        yield domain
    finally:
        executor.shutdown(timeout_sec=1.0)
        server.destroy()
        node.destroy_node()
        ctx.shutdown()


def _until(client: ActionClient, gid: bytes, done, timeout_s: float = 10.0) -> GoalState:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        client.poll()
        if done(client.state(gid)):
            break
        time.sleep(0.02)
    return client.state(gid)


def test_goals_to_a_real_ros2_action_server_succeed_abort_are_rejected_and_cancel(
    fibonacci_server,
):
    from cyclonedds.domain import DomainParticipant

    from tests import dds_fibonacci as fib

    types = ActionTypes(fib.SendGoalRequest, fib.SendGoalResponse, fib.FeedbackMessage)
    client = ActionClient(DomainParticipant(fibonacci_server), "robot/fibonacci", types)
    assert client.wait_ready(20.0), "the rclpy action server was not discovered"
    time.sleep(0.5)  # the server's reply writer matched with our reader too
    done = GoalState.done.fget

    ok = client.send(fib.Goal(order=5))
    assert _until(client, ok, done) == GoalState.SUCCEEDED
    assert list(client.feedback[ok].sequence) == [0, 1, 1, 2, 3, 5, 8]  # the last feedback
    aborted = client.send(fib.Goal(order=ABORT_ORDER))
    assert _until(client, aborted, done) == GoalState.ABORTED
    rejected = client.send(fib.Goal(order=-1))
    assert _until(client, rejected, done) == GoalState.REJECTED
    long = client.send(fib.Goal(order=200))  # 10 s of work
    assert _until(client, long, lambda s: long in client.feedback) == GoalState.ACTIVE
    client.cancel(long)
    assert _until(client, long, done) == GoalState.CANCELED
    assert len(client.feedback[long].sequence) < 100  # stopped well before the end
    # each goal kept its own outcome
    assert [client.state(g) for g in (ok, aborted, rejected)] == [
        GoalState.SUCCEEDED,
        GoalState.ABORTED,
        GoalState.REJECTED,
    ]


class Nav2StandIn:
    """Nav2's navigate_to_pose on DDS, as the robot's bt_navigator offers it (the unit's
    collaborator; nav2_msgs is not on PyPI): goals at x < 0 abort, at x >= 50 run until
    canceled, the rest succeed after ``RUN_S``."""

    RUN_S = 0.3

    def __init__(self, domain: int, name: str) -> None:
        from cyclonedds.core import Policy, Qos
        from cyclonedds.domain import DomainParticipant
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        from agents import dds_types as t

        cdr = Policy.DataRepresentation(use_cdrv0_representation=True)
        rel = Policy.Reliability.Reliable(0)
        q = Qos(rel, Policy.History.KeepLast(10), cdr)
        latched = Qos(rel, Policy.Durability.TransientLocal, Policy.History.KeepLast(1), cdr)
        dp = self.dp = DomainParticipant(domain)
        a = f"{name}/_action/"

        def topic(p, what, kind):
            return Topic(dp, f"{p}/{a}{what}", kind)

        self.requests = DataReader(
            dp, topic("rq", "send_goalRequest", t.NavigateToPoseSendGoalRequest), q
        )
        self.replies = DataWriter(
            dp, topic("rr", "send_goalReply", t.NavigateToPoseSendGoalResponse), q
        )
        self.cancels = DataReader(dp, topic("rq", "cancel_goalRequest", t.CancelGoalRequest), q)
        self.status = DataWriter(dp, topic("rt", "status", t.GoalStatusArray), latched)
        self.feedback = DataWriter(dp, topic("rt", "feedback", t.NavigateToPoseFeedbackMessage), q)
        self.t = t
        self.goals: dict[bytes, list] = {}  # id -> [goal, status, started]
        self.received: list = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _publish(self) -> None:
        t = self.t
        self.status.write(
            t.GoalStatusArray(
                [
                    t.GoalStatus(t.GoalInfo(t.UUID(list(g)), t.Time(0, 0)), s)
                    for g, (_, s, _) in self.goals.items()
                ]
            )
        )

    def _serve(self) -> None:
        t = self.t
        while not self._stop.wait(0.02):
            for req in self.requests.take(N=10):
                if not hasattr(req, "goal_id"):  # a client gone, not a request
                    continue
                gid = bytes(req.goal_id.uuid)
                self.received.append(req.goal)
                self.replies.write(t.NavigateToPoseSendGoalResponse(True, t.Time(0, 0)))
                self.goals[gid] = [req.goal, 2, time.monotonic()]  # executing
                fb = t.NavigateToPoseFeedback(
                    req.goal.pose, t.Duration(0, 0), t.Duration(1, 0), 0, 1.25
                )
                self.feedback.write(t.NavigateToPoseFeedbackMessage(req.goal_id, fb))
                self._publish()
            for c in self.cancels.take(N=10):
                if not hasattr(c, "goal_info"):
                    continue
                g = self.goals.get(bytes(c.goal_info.goal_id.uuid))
                if g is not None and g[1] == 2:
                    g[1] = 5  # canceled
                    self._publish()
            for g in list(self.goals.values()):
                x = g[0].pose.pose.position.x
                if g[1] == 2 and x < 50 and time.monotonic() - g[2] > self.RUN_S:
                    g[1] = 6 if x < 0 else 4  # aborted, succeeded
                    self._publish()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)


def test_the_agents_nav2_goals_carry_the_pose_and_end_as_nav2_says():
    from agents.ros2_action import Nav2Goals

    domain = random.randint(1, 200)
    server = Nav2StandIn(domain, "tb4/navigate_to_pose")
    nav = Nav2Goals(domain, "tb4/navigate_to_pose", "map")
    try:
        deadline = time.monotonic() + 20.0
        while not nav.client.ready() and time.monotonic() < deadline:
            time.sleep(0.05)

        def outcome():
            end = time.monotonic() + 10.0
            while time.monotonic() < end:
                done = nav.outcome()
                if done is not None:
                    return done
                time.sleep(0.02)
            return None

        nav.navigate(1, (2.0, 3.0), 0.5, 1234.25)
        done = outcome()
        assert (done.target, done.state) == (1, GoalState.SUCCEEDED)
        assert "1.2 m from the goal" in done.detail  # Nav2's feedback, in the log line
        g = server.received[-1]
        assert g.pose.header.frame_id == "map" and g.pose.header.stamp.sec == 1234
        assert (g.pose.pose.position.x, g.pose.pose.position.y) == (2.0, 3.0)
        assert 2 * math.atan2(g.pose.pose.orientation.z, g.pose.pose.orientation.w) == (
            pytest.approx(0.5)
        )
        nav.navigate(2, (-1.0, 0.0), 0.0, 1235.0)
        assert outcome().state == GoalState.ABORTED
        nav.navigate(3, (99.0, 0.0), 0.0, 1236.0)  # runs until canceled
        time.sleep(0.5)
        nav.navigate(4, (1.0, 1.0), 0.0, 1237.0)  # a reassignment cancels goal 3
        done = outcome()
        assert (done.target, done.state) == (4, GoalState.SUCCEEDED)
        assert sorted(s for _, s, _ in server.goals.values()) == [4, 4, 5, 6]
    finally:
        nav.close()
        server.close()
