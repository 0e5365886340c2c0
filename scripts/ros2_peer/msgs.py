"""ROS 2 message types as Cyclone DDS IDL structs, written from the .msg definitions (field order
is the wire order) with ROS 2's DDS type names (`pkg::msg::dds_::Type_`). Independent of handeye's
Rust definitions: these are what a ROS 2 node built on rmw_cyclonedds puts on the wire."""

from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float64, int8, int32, int64, sequence, uint8, uint16, uint32, uint64


def _n(pkg, kind, name):
    return f"{pkg}::{kind}::dds_::{name}_"


@dataclass
class Time(IdlStruct, typename=_n("builtin_interfaces", "msg", "Time")):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Duration(IdlStruct, typename=_n("builtin_interfaces", "msg", "Duration")):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header(IdlStruct, typename=_n("std_msgs", "msg", "Header")):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class Vector3(IdlStruct, typename=_n("geometry_msgs", "msg", "Vector3")):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Quaternion(IdlStruct, typename=_n("geometry_msgs", "msg", "Quaternion")):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@dataclass
class Transform(IdlStruct, typename=_n("geometry_msgs", "msg", "Transform")):
    translation: Vector3 = field(default_factory=Vector3)
    rotation: Quaternion = field(default_factory=Quaternion)


@dataclass
class TransformStamped(IdlStruct, typename=_n("geometry_msgs", "msg", "TransformStamped")):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    transform: Transform = field(default_factory=Transform)


@dataclass
class TFMessage(IdlStruct, typename=_n("tf2_msgs", "msg", "TFMessage")):
    transforms: sequence[TransformStamped] = field(default_factory=list)


@dataclass
class JointState(IdlStruct, typename=_n("sensor_msgs", "msg", "JointState")):
    header: Header = field(default_factory=Header)
    name: sequence[str] = field(default_factory=list)
    position: sequence[float64] = field(default_factory=list)
    velocity: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)


@dataclass
class Image(IdlStruct, typename=_n("sensor_msgs", "msg", "Image")):
    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    encoding: str = ""
    is_bigendian: uint8 = 0
    step: uint32 = 0
    data: sequence[uint8] = field(default_factory=list)


@dataclass
class CompressedImage(IdlStruct, typename=_n("sensor_msgs", "msg", "CompressedImage")):
    header: Header = field(default_factory=Header)
    format: str = ""
    data: sequence[uint8] = field(default_factory=list)


@dataclass
class RegionOfInterest(IdlStruct, typename=_n("sensor_msgs", "msg", "RegionOfInterest")):
    x_offset: uint32 = 0
    y_offset: uint32 = 0
    height: uint32 = 0
    width: uint32 = 0
    do_rectify: bool = False


@dataclass
class CameraInfo(IdlStruct, typename=_n("sensor_msgs", "msg", "CameraInfo")):
    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    distortion_model: str = ""
    d: sequence[float64] = field(default_factory=list)
    k: array[float64, 9] = field(default_factory=lambda: [0.0] * 9)
    r: array[float64, 9] = field(default_factory=lambda: [0.0] * 9)
    p: array[float64, 12] = field(default_factory=lambda: [0.0] * 12)
    binning_x: uint32 = 0
    binning_y: uint32 = 0
    roi: RegionOfInterest = field(default_factory=RegionOfInterest)


@dataclass
class JointTrajectoryPoint(IdlStruct, typename=_n("trajectory_msgs", "msg", "JointTrajectoryPoint")):
    positions: sequence[float64] = field(default_factory=list)
    velocities: sequence[float64] = field(default_factory=list)
    accelerations: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)
    time_from_start: Duration = field(default_factory=Duration)


@dataclass
class JointTrajectory(IdlStruct, typename=_n("trajectory_msgs", "msg", "JointTrajectory")):
    header: Header = field(default_factory=Header)
    joint_names: sequence[str] = field(default_factory=list)
    points: sequence[JointTrajectoryPoint] = field(default_factory=list)


@dataclass
class Twist(IdlStruct, typename=_n("geometry_msgs", "msg", "Twist")):
    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@dataclass
class MultiDOFJointTrajectoryPoint(IdlStruct, typename=_n("trajectory_msgs", "msg", "MultiDOFJointTrajectoryPoint")):
    transforms: sequence[Transform] = field(default_factory=list)
    velocities: sequence[Twist] = field(default_factory=list)
    accelerations: sequence[Twist] = field(default_factory=list)
    time_from_start: Duration = field(default_factory=Duration)


@dataclass
class MultiDOFJointTrajectory(IdlStruct, typename=_n("trajectory_msgs", "msg", "MultiDOFJointTrajectory")):
    header: Header = field(default_factory=Header)
    joint_names: sequence[str] = field(default_factory=list)
    points: sequence[MultiDOFJointTrajectoryPoint] = field(default_factory=list)


@dataclass
class JointTolerance(IdlStruct, typename=_n("control_msgs", "msg", "JointTolerance")):
    name: str = ""
    position: float64 = 0.0
    velocity: float64 = 0.0
    acceleration: float64 = 0.0


@dataclass
class JointComponentTolerance(IdlStruct, typename=_n("control_msgs", "msg", "JointComponentTolerance")):
    joint_name: str = ""
    component: uint16 = 0
    position: float64 = 0.0
    velocity: float64 = 0.0
    acceleration: float64 = 0.0


A = "control_msgs::action::dds_::FollowJointTrajectory"


@dataclass
class FJTGoal(IdlStruct, typename=A + "_Goal_"):
    trajectory: JointTrajectory = field(default_factory=JointTrajectory)
    multi_dof_trajectory: MultiDOFJointTrajectory = field(default_factory=MultiDOFJointTrajectory)
    path_tolerance: sequence[JointTolerance] = field(default_factory=list)
    component_path_tolerance: sequence[JointComponentTolerance] = field(default_factory=list)
    goal_tolerance: sequence[JointTolerance] = field(default_factory=list)
    component_goal_tolerance: sequence[JointComponentTolerance] = field(default_factory=list)
    goal_time_tolerance: Duration = field(default_factory=Duration)


@dataclass
class FJTResult(IdlStruct, typename=A + "_Result_"):
    error_code: int32 = 0
    error_string: str = ""


@dataclass
class FJTFeedback(IdlStruct, typename=A + "_Feedback_"):
    header: Header = field(default_factory=Header)
    joint_names: sequence[str] = field(default_factory=list)
    desired: JointTrajectoryPoint = field(default_factory=JointTrajectoryPoint)
    actual: JointTrajectoryPoint = field(default_factory=JointTrajectoryPoint)
    error: JointTrajectoryPoint = field(default_factory=JointTrajectoryPoint)
    multi_dof_joint_names: sequence[str] = field(default_factory=list)
    multi_dof_desired: MultiDOFJointTrajectoryPoint = field(default_factory=MultiDOFJointTrajectoryPoint)
    multi_dof_actual: MultiDOFJointTrajectoryPoint = field(default_factory=MultiDOFJointTrajectoryPoint)
    multi_dof_error: MultiDOFJointTrajectoryPoint = field(default_factory=MultiDOFJointTrajectoryPoint)


@dataclass
class UUID(IdlStruct, typename=_n("unique_identifier_msgs", "msg", "UUID")):
    uuid: array[uint8, 16] = field(default_factory=lambda: [0] * 16)


@dataclass
class GoalInfo(IdlStruct, typename=_n("action_msgs", "msg", "GoalInfo")):
    goal_id: UUID = field(default_factory=UUID)
    stamp: Time = field(default_factory=Time)


@dataclass
class GoalStatus(IdlStruct, typename=_n("action_msgs", "msg", "GoalStatus")):
    goal_info: GoalInfo = field(default_factory=GoalInfo)
    status: int8 = 0


@dataclass
class GoalStatusArray(IdlStruct, typename=_n("action_msgs", "msg", "GoalStatusArray")):
    status_list: sequence[GoalStatus] = field(default_factory=list)


# Services and actions the way rmw_cyclonedds puts them on the wire: every request and reply
# starts with the request header (the client's 64-bit id and a sequence number), then the fields.
@dataclass
class SendGoalRequest(IdlStruct, typename=A + "_SendGoal_Request_"):
    client_id: uint64 = 0
    seq: int64 = 0
    goal_id: UUID = field(default_factory=UUID)
    goal: FJTGoal = field(default_factory=FJTGoal)


@dataclass
class SendGoalReply(IdlStruct, typename=A + "_SendGoal_Response_"):
    client_id: uint64 = 0
    seq: int64 = 0
    accepted: bool = False
    stamp: Time = field(default_factory=Time)


@dataclass
class GetResultRequest(IdlStruct, typename=A + "_GetResult_Request_"):
    client_id: uint64 = 0
    seq: int64 = 0
    goal_id: UUID = field(default_factory=UUID)


@dataclass
class GetResultReply(IdlStruct, typename=A + "_GetResult_Response_"):
    client_id: uint64 = 0
    seq: int64 = 0
    status: int8 = 0
    result: FJTResult = field(default_factory=FJTResult)


@dataclass
class FeedbackMessage(IdlStruct, typename=A + "_FeedbackMessage_"):
    goal_id: UUID = field(default_factory=UUID)
    feedback: FJTFeedback = field(default_factory=FJTFeedback)


@dataclass
class CancelGoalRequest(IdlStruct, typename="action_msgs::srv::dds_::CancelGoal_Request_"):
    client_id: uint64 = 0
    seq: int64 = 0
    goal_info: GoalInfo = field(default_factory=GoalInfo)


@dataclass
class CancelGoalReply(IdlStruct, typename="action_msgs::srv::dds_::CancelGoal_Response_"):
    client_id: uint64 = 0
    seq: int64 = 0
    return_code: int8 = 0
    goals_canceling: sequence[GoalInfo] = field(default_factory=list)


@dataclass
class Bool(IdlStruct, typename=_n("std_msgs", "msg", "Bool")):
    data: bool = False


# controller_manager_msgs/SwitchController, as each distribution's ros2_control defines it (the
# .srv files of its humble and jazzy branches): Humble keeps the deprecated start/stop lists and
# start_asap among the fields; the reply's `message` is Jazzy's.
SWITCH = "controller_manager_msgs::srv::dds_::SwitchController"


@dataclass
class SwitchRequestHumble(IdlStruct, typename=SWITCH + "_Request_"):
    client_id: uint64 = 0
    seq: int64 = 0
    activate_controllers: sequence[str] = field(default_factory=list)
    deactivate_controllers: sequence[str] = field(default_factory=list)
    start_controllers: sequence[str] = field(default_factory=list)
    stop_controllers: sequence[str] = field(default_factory=list)
    strictness: int32 = 0
    start_asap: bool = False
    activate_asap: bool = False
    timeout: Duration = field(default_factory=Duration)


@dataclass
class SwitchReplyHumble(IdlStruct, typename=SWITCH + "_Response_"):
    client_id: uint64 = 0
    seq: int64 = 0
    ok: bool = False


@dataclass
class SwitchRequestJazzy(IdlStruct, typename=SWITCH + "_Request_"):
    client_id: uint64 = 0
    seq: int64 = 0
    activate_controllers: sequence[str] = field(default_factory=list)
    deactivate_controllers: sequence[str] = field(default_factory=list)
    strictness: int32 = 0
    activate_asap: bool = False
    timeout: Duration = field(default_factory=Duration)


@dataclass
class SwitchReplyJazzy(IdlStruct, typename=SWITCH + "_Response_"):
    client_id: uint64 = 0
    seq: int64 = 0
    ok: bool = False
    message: str = ""
