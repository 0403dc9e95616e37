"""test_msgs/action/Fibonacci as Cyclone DDS IDL structs: an action a real rclpy server
offers from PyPI's ROS 2 packages, to test ``agents.ros2_action`` against. (No
postponed annotations: Cyclone DDS resolves field types from this module's names.)"""

from dataclasses import dataclass

import cyclonedds.idl.annotations as annotate
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import int32, sequence

from agents.dds_types import UUID, Time

FIB = "test_msgs::action::dds_::Fibonacci_"


@dataclass
@annotate.final
class Goal(IdlStruct, typename=FIB + "Goal_"):
    order: int32


@dataclass
@annotate.final
class Feedback(IdlStruct, typename=FIB + "Feedback_"):
    sequence: sequence[int32]


@dataclass
@annotate.final
class SendGoalRequest(IdlStruct, typename=FIB + "SendGoal_Request_"):
    goal_id: UUID
    goal: Goal


@dataclass
@annotate.final
class SendGoalResponse(IdlStruct, typename=FIB + "SendGoal_Response_"):
    accepted: bool
    stamp: Time


@dataclass
@annotate.final
class FeedbackMessage(IdlStruct, typename=FIB + "FeedbackMessage_"):
    goal_id: UUID
    feedback: Feedback
