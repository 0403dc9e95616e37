"""ROS 2 messages that are not on PyPI as Cyclone DDS IDL structs, under the names ROS 2
gives them in DDS (``tf2_msgs::msg::dds_::TFMessage_``): read and written as plain CDR,
they are the messages of every ROS 2 node on the domain. tf2_msgs/TFMessage for
``agents.ros2_tf``; action_msgs and nav2_msgs/action/NavigateToPose (ROS 2 Jazzy's
definitions) for ``agents.ros2_action``.

Imports cyclonedds: import this module only where it is installed. (No postponed
annotations here: Cyclone DDS resolves the field types from this module's names.)
"""

import math
from dataclasses import dataclass

import cyclonedds.idl.annotations as annotate
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import (
    array,
    float32,
    float64,
    int8,
    int16,
    int32,
    sequence,
    uint8,
    uint16,
    uint32,
)


@dataclass
@annotate.final
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


def time_of(t_s: float) -> Time:
    """builtin_interfaces/Time of ``t_s`` seconds."""
    sec = math.floor(t_s)
    return Time(sec, min(int((t_s - sec) * 1e9), 999_999_999))


@dataclass
@annotate.final
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
@annotate.final
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
@annotate.final
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclass
@annotate.final
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
@annotate.final
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
@annotate.final
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped]


# -- geometry_msgs/PoseStamped and builtin_interfaces/Duration ---------------------------


@dataclass
@annotate.final
class Duration(IdlStruct, typename="builtin_interfaces::msg::dds_::Duration_"):
    sec: int32
    nanosec: uint32


@dataclass
@annotate.final
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64
    y: float64
    z: float64


@dataclass
@annotate.final
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
@annotate.final
class PoseStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    header: Header
    pose: Pose


# -- action_msgs: what every action's protocol shares --------------------------------------


@dataclass
@annotate.final
class UUID(IdlStruct, typename="unique_identifier_msgs::msg::dds_::UUID_"):
    uuid: array[uint8, 16]


@dataclass
@annotate.final
class GoalInfo(IdlStruct, typename="action_msgs::msg::dds_::GoalInfo_"):
    goal_id: UUID
    stamp: Time


@dataclass
@annotate.final
class GoalStatus(IdlStruct, typename="action_msgs::msg::dds_::GoalStatus_"):
    goal_info: GoalInfo
    status: int8


@dataclass
@annotate.final
class GoalStatusArray(IdlStruct, typename="action_msgs::msg::dds_::GoalStatusArray_"):
    status_list: sequence[GoalStatus]


@dataclass
@annotate.final
class CancelGoalRequest(IdlStruct, typename="action_msgs::srv::dds_::CancelGoal_Request_"):
    goal_info: GoalInfo


@dataclass
@annotate.final
class CancelGoalResponse(IdlStruct, typename="action_msgs::srv::dds_::CancelGoal_Response_"):
    return_code: int8
    goals_canceling: sequence[GoalInfo]


# -- nav2_msgs/action/NavigateToPose (Jazzy) ------------------------------------------------

NAV2 = "nav2_msgs::action::dds_::NavigateToPose_"


@dataclass
@annotate.final
class NavigateToPoseGoal(IdlStruct, typename=NAV2 + "Goal_"):
    pose: PoseStamped
    behavior_tree: str


@dataclass
@annotate.final
class NavigateToPoseResult(IdlStruct, typename=NAV2 + "Result_"):
    error_code: uint16
    error_msg: str


@dataclass
@annotate.final
class NavigateToPoseFeedback(IdlStruct, typename=NAV2 + "Feedback_"):
    current_pose: PoseStamped
    navigation_time: Duration
    estimated_time_remaining: Duration
    number_of_recoveries: int16
    distance_remaining: float32


@dataclass
@annotate.final
class NavigateToPoseSendGoalRequest(IdlStruct, typename=NAV2 + "SendGoal_Request_"):
    goal_id: UUID
    goal: NavigateToPoseGoal


@dataclass
@annotate.final
class NavigateToPoseSendGoalResponse(IdlStruct, typename=NAV2 + "SendGoal_Response_"):
    accepted: bool
    stamp: Time


@dataclass
@annotate.final
class NavigateToPoseFeedbackMessage(IdlStruct, typename=NAV2 + "FeedbackMessage_"):
    goal_id: UUID
    feedback: NavigateToPoseFeedback
