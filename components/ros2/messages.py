"""The ROS 2 message types ``ros2.bridge`` maps to and from a component's variables: for each type,
its fields (a fixed part of the message, or a float64 sequence of any length), how a field's values
are read from a message and how a message is built from the values of its fields. No I/O: the
messages are rosbags' classes (ROS 2 Jazzy definitions), which the caller serializes as CDR.

Fields and conventions (docs/guides/ros2.md, "A ROS 2 node in the loop"):

- vectors in message order: a wrench is [force x y z, torque x y z], a twist [linear x y z,
  angular x y z]; quaternions [x, y, z, w], as in the recording;
- ``JointTrajectory``'s fields are those of its first point (``points[0]``);
- a field the bridge builds no value for is left neutral: an empty sequence, a zero vector, the
  identity quaternion; in an ``Imu``, the first element of a part's covariance set to -1 (REP 145:
  not provided).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from components.errors import ComponentError

IDENTITY_XYZW = (0.0, 0.0, 0.0, 1.0)
NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class Field:
    """A part of a message the bridge reads or writes: ``size`` values (None: a float64 sequence of
    any length), in ``unit`` (None: the variable's own, for sequences such as joint positions);
    ``parts``: the message parts it covers (two variables on one topic cannot share one);
    ``neutral``: its value when nothing is given (zeros unless said)."""

    name: str
    size: int | None
    unit: str | None
    parts: tuple[str, ...]
    read: Callable[[Any], np.ndarray]  # the message: a rosbags dataclass of the map's type
    neutral: tuple[float, ...] | None = None


@dataclass(frozen=True)
class MessageMap:
    """A supported message type: its ``fields`` by name, whether it has a header (``stamped``),
    whether it carries joint names (``named``: JointState ``name``, JointTrajectory ``joint_names``),
    and ``build(types, stamp_ns, frame_id, names, values)`` -> a message (``values``: field -> array)."""

    msgtype: str
    fields: dict[str, Field]
    stamped: bool
    named: bool
    build: Callable[..., object]


def _vector3(v) -> np.ndarray:
    return np.array([v.x, v.y, v.z], dtype=np.float64)


def _quaternion(q) -> np.ndarray:
    return np.array([q.x, q.y, q.z, q.w], dtype=np.float64)


def _sequence(values) -> np.ndarray:
    return np.array(values, dtype=np.float64)


def _first_point(message):
    if len(message.points) == 0:
        raise ComponentError("the JointTrajectory has no points (the bridge reads points[0])")
    return message.points[0]


def ros_time(types, ns: int):
    """builtin_interfaces/Time of ROS time ``ns`` (ns since 1970)."""
    return types["builtin_interfaces/msg/Time"](sec=int(ns // NS_PER_S), nanosec=int(ns % NS_PER_S))


def stamp_ns(message) -> int:
    """The header stamp of a message, as ns since 1970."""
    stamp = message.header.stamp
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def cdr_stamp(cdr: bytes) -> int:
    """The header stamp (ns since 1970) of a serialized message whose first field is its header,
    read from the CDR bytes without deserializing the rest: after the 4-byte encapsulation header
    (representation 0x0000 big endian, 0x0001 little endian), int32 sec and uint32 nanosec."""
    if len(cdr) < 12 or cdr[0] != 0 or cdr[1] not in (0, 1):
        raise ValueError(f"not a plain CDR message with a header ({len(cdr)} bytes, starting {bytes(cdr[:4]).hex()})")
    sec, nanosec = struct.unpack_from("<iI" if cdr[1] else ">iI", cdr, 4)
    return sec * NS_PER_S + nanosec


def _header(types, ns: int, frame_id: str):
    return types["std_msgs/msg/Header"](stamp=ros_time(types, ns), frame_id=frame_id)


def _v3(types, values):
    return types["geometry_msgs/msg/Vector3"](x=float(values[0]), y=float(values[1]), z=float(values[2]))


def _point(types, values):
    return types["geometry_msgs/msg/Point"](x=float(values[0]), y=float(values[1]), z=float(values[2]))


def _quat(types, values):
    return types["geometry_msgs/msg/Quaternion"](
        x=float(values[0]), y=float(values[1]), z=float(values[2]), w=float(values[3])
    )


def _part(values: dict, name: str, whole: str, at: slice, neutral=(0.0, 0.0, 0.0)) -> np.ndarray:
    """A part's values: from its own field, from the field that covers it (``whole`` at ``at``), or neutral."""
    if name in values:
        return values[name]
    if whole in values:
        return values[whole][at]
    return np.asarray(neutral, dtype=np.float64)


def _build_float64(types, ns, frame_id, names, values):
    return types["std_msgs/msg/Float64"](data=float(values.get("data", np.zeros(1))[0]))


def _build_array(types, ns, frame_id, names, values):
    data = values.get("data", np.empty(0)).astype(np.float64)
    layout = types["std_msgs/msg/MultiArrayLayout"](
        dim=[types["std_msgs/msg/MultiArrayDimension"](label="data", size=data.size, stride=data.size)], data_offset=0
    )
    return types["std_msgs/msg/Float64MultiArray"](layout=layout, data=data)


def _build_joint_state(types, ns, frame_id, names, values):
    return types["sensor_msgs/msg/JointState"](
        header=_header(types, ns, frame_id),
        name=list(names),
        **{f: values.get(f, np.empty(0)).astype(np.float64) for f in ("position", "velocity", "effort")},
    )


def _build_trajectory(types, ns, frame_id, names, values):
    point = types["trajectory_msgs/msg/JointTrajectoryPoint"](
        **{
            f: values.get(f, np.empty(0)).astype(np.float64)
            for f in ("positions", "velocities", "accelerations", "effort")
        },
        time_from_start=types["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
    )
    return types["trajectory_msgs/msg/JointTrajectory"](
        header=_header(types, ns, frame_id), joint_names=list(names), points=[point]
    )


def _build_wrench(types, ns, frame_id, names, values):
    wrench = types["geometry_msgs/msg/Wrench"](
        force=_v3(types, _part(values, "force", "wrench", slice(0, 3))),
        torque=_v3(types, _part(values, "torque", "wrench", slice(3, 6))),
    )
    return types["geometry_msgs/msg/WrenchStamped"](header=_header(types, ns, frame_id), wrench=wrench)


def _build_pose(types, ns, frame_id, names, values):
    pose = types["geometry_msgs/msg/Pose"](
        position=_point(types, values.get("position", np.zeros(3))),
        orientation=_quat(types, values.get("orientation", np.asarray(IDENTITY_XYZW))),
    )
    return types["geometry_msgs/msg/PoseStamped"](header=_header(types, ns, frame_id), pose=pose)


def _build_twist(types, ns, frame_id, names, values):
    twist = types["geometry_msgs/msg/Twist"](
        linear=_v3(types, _part(values, "linear", "twist", slice(0, 3))),
        angular=_v3(types, _part(values, "angular", "twist", slice(3, 6))),
    )
    return types["geometry_msgs/msg/TwistStamped"](header=_header(types, ns, frame_id), twist=twist)


def _covariance(given: bool) -> np.ndarray:
    covariance = np.zeros(9)
    if not given:
        covariance[0] = -1.0  # REP 145: this part is not provided
    return covariance


def _build_imu(types, ns, frame_id, names, values):
    return types["sensor_msgs/msg/Imu"](
        header=_header(types, ns, frame_id),
        orientation=_quat(types, values.get("orientation", np.asarray(IDENTITY_XYZW))),
        orientation_covariance=_covariance("orientation" in values),
        angular_velocity=_v3(types, values.get("angular_velocity", np.zeros(3))),
        angular_velocity_covariance=_covariance("angular_velocity" in values),
        linear_acceleration=_v3(types, values.get("linear_acceleration", np.zeros(3))),
        linear_acceleration_covariance=_covariance("linear_acceleration" in values),
    )


def _fields(*fields: Field) -> dict[str, Field]:
    return {f.name: f for f in fields}


def _attribute(name: str):
    return lambda m: _sequence(getattr(m, name))


def _of_point(name: str):
    return lambda m: _sequence(getattr(_first_point(m), name))


def _concat(first: Callable, second: Callable):
    return lambda m: np.concatenate((first(m), second(m)))


_force = lambda m: _vector3(m.wrench.force)  # noqa: E731 (a table of one-line readers)
_torque = lambda m: _vector3(m.wrench.torque)  # noqa: E731
_position = lambda m: _vector3(m.pose.position)  # noqa: E731
_orientation = lambda m: _quaternion(m.pose.orientation)  # noqa: E731
_linear = lambda m: _vector3(m.twist.linear)  # noqa: E731
_angular = lambda m: _vector3(m.twist.angular)  # noqa: E731


def _array_data(message) -> np.ndarray:
    return _sequence(message.data[message.layout.data_offset :])  # data_offset: padding before the data


MAPS: dict[str, MessageMap] = {
    m.msgtype: m
    for m in (
        MessageMap(
            "std_msgs/msg/Float64",
            _fields(Field("data", 1, None, ("data",), lambda m: np.array([m.data], dtype=np.float64))),
            stamped=False,
            named=False,
            build=_build_float64,
        ),
        MessageMap(
            "std_msgs/msg/Float64MultiArray",
            _fields(Field("data", None, None, ("data",), _array_data)),
            stamped=False,
            named=False,
            build=_build_array,
        ),
        MessageMap(
            "sensor_msgs/msg/JointState",
            _fields(*(Field(f, None, None, (f,), _attribute(f)) for f in ("position", "velocity", "effort"))),
            stamped=True,
            named=True,
            build=_build_joint_state,
        ),
        MessageMap(
            "trajectory_msgs/msg/JointTrajectory",
            _fields(
                *(
                    Field(f, None, None, (f,), _of_point(f))
                    for f in ("positions", "velocities", "accelerations", "effort")
                )
            ),
            stamped=True,
            named=True,
            build=_build_trajectory,
        ),
        MessageMap(
            "geometry_msgs/msg/WrenchStamped",
            _fields(
                Field("wrench", 6, "N, N*m", ("force", "torque"), _concat(_force, _torque)),
                Field("force", 3, "N", ("force",), _force),
                Field("torque", 3, "N*m", ("torque",), _torque),
            ),
            stamped=True,
            named=False,
            build=_build_wrench,
        ),
        MessageMap(
            "geometry_msgs/msg/PoseStamped",
            _fields(
                Field("position", 3, "m", ("position",), _position),
                Field("orientation", 4, "1", ("orientation",), _orientation, neutral=IDENTITY_XYZW),
            ),
            stamped=True,
            named=False,
            build=_build_pose,
        ),
        MessageMap(
            "geometry_msgs/msg/TwistStamped",
            _fields(
                Field("twist", 6, "m/s, rad/s", ("linear", "angular"), _concat(_linear, _angular)),
                Field("linear", 3, "m/s", ("linear",), _linear),
                Field("angular", 3, "rad/s", ("angular",), _angular),
            ),
            stamped=True,
            named=False,
            build=_build_twist,
        ),
        MessageMap(
            "sensor_msgs/msg/Imu",
            _fields(
                Field(
                    "orientation", 4, "1", ("orientation",), lambda m: _quaternion(m.orientation), neutral=IDENTITY_XYZW
                ),
                Field("angular_velocity", 3, "rad/s", ("angular_velocity",), lambda m: _vector3(m.angular_velocity)),
                Field(
                    "linear_acceleration",
                    3,
                    "m/s^2",
                    ("linear_acceleration",),
                    lambda m: _vector3(m.linear_acceleration),
                ),
            ),
            stamped=True,
            named=False,
            build=_build_imu,
        ),
    )
}


def supported() -> str:
    """The supported types and their fields, for error messages: ``std_msgs/msg/Float64 (data), ...``."""
    return ", ".join(f"{t} ({' | '.join(m.fields)})" for t, m in MAPS.items())


def read(message_map: MessageMap, field: str, message, names: list[str] | None) -> np.ndarray:
    """The values of ``field`` in ``message`` (float64); with ``names``, the joints' values picked by
    name from the message's (JointState ``name``, JointTrajectory ``joint_names``), in that order."""
    values = message_map.fields[field].read(message)
    if names is None:
        return values
    given = list(message.name if message_map.msgtype == "sensor_msgs/msg/JointState" else message.joint_names)
    missing = [n for n in names if n not in given]
    if missing:
        raise ComponentError(f"joint {missing[0]!r} is not in the message's joint names {given}")
    if len(values) != len(given):
        raise ComponentError(f"{field} holds {len(values)} values for {len(given)} joint names")
    return values[[given.index(n) for n in names]]
