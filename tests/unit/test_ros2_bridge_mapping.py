"""``ros2.bridge`` without a run: its message mapping against a second CDR implementation
(``mcap-ros2-support``, not rosbags), its lockstep rules (components/ros2/lockstep.py), and the
configuration errors ``orchestrator check`` reports (exit 2), each naming its key."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from components.ros2 import lockstep, messages
from components.ros2.bridge import Ros2Bridge
from components.sdk import RunSettings, resolve_parameters

STAMP = 1_663_502_400_123_456_789  # 2022-09-18T12:00:00.123456789Z as ROS time (ns)
JOINTS = ["shoulder", "elbow", "wrist"]


@pytest.fixture(scope="module")
def typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def _xyz(m):
    return [m.x, m.y, m.z]


def _xyzw(m):
    return [m.x, m.y, m.z, m.w]


# how the second reader finds each field in its own decoded message (attribute paths written here,
# from the message definitions, not taken from components/ros2/messages.py)
INDEPENDENT = {
    ("std_msgs/msg/Float64", "data"): lambda m: [m.data],
    ("std_msgs/msg/Float64MultiArray", "data"): lambda m: list(m.data),
    ("sensor_msgs/msg/JointState", "position"): lambda m: list(m.position),
    ("sensor_msgs/msg/JointState", "velocity"): lambda m: list(m.velocity),
    ("sensor_msgs/msg/JointState", "effort"): lambda m: list(m.effort),
    ("trajectory_msgs/msg/JointTrajectory", "positions"): lambda m: list(m.points[0].positions),
    ("trajectory_msgs/msg/JointTrajectory", "velocities"): lambda m: list(m.points[0].velocities),
    ("trajectory_msgs/msg/JointTrajectory", "accelerations"): lambda m: list(m.points[0].accelerations),
    ("trajectory_msgs/msg/JointTrajectory", "effort"): lambda m: list(m.points[0].effort),
    ("geometry_msgs/msg/WrenchStamped", "wrench"): lambda m: _xyz(m.wrench.force) + _xyz(m.wrench.torque),
    ("geometry_msgs/msg/WrenchStamped", "force"): lambda m: _xyz(m.wrench.force),
    ("geometry_msgs/msg/WrenchStamped", "torque"): lambda m: _xyz(m.wrench.torque),
    ("geometry_msgs/msg/PoseStamped", "position"): lambda m: _xyz(m.pose.position),
    ("geometry_msgs/msg/PoseStamped", "orientation"): lambda m: _xyzw(m.pose.orientation),
    ("geometry_msgs/msg/TwistStamped", "twist"): lambda m: _xyz(m.twist.linear) + _xyz(m.twist.angular),
    ("geometry_msgs/msg/TwistStamped", "linear"): lambda m: _xyz(m.twist.linear),
    ("geometry_msgs/msg/TwistStamped", "angular"): lambda m: _xyz(m.twist.angular),
    ("sensor_msgs/msg/Imu", "orientation"): lambda m: _xyzw(m.orientation),
    ("sensor_msgs/msg/Imu", "angular_velocity"): lambda m: _xyz(m.angular_velocity),
    ("sensor_msgs/msg/Imu", "linear_acceleration"): lambda m: _xyz(m.linear_acceleration),
}
CASES = sorted(INDEPENDENT)


def _values(field: messages.Field, seed: int) -> np.ndarray:
    """Values no rounding leaves alone by chance: irrational-looking float64s, signs mixed."""
    rng = np.random.default_rng(seed)
    return rng.normal(size=field.size or len(JOINTS)) * np.pi


def _second_reader(msgtype: str, typestore):
    from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

    definition = typestore.generate_msgdef(msgtype, ros_version=2)[0]
    return generate_dynamic(msgtype, definition)[msgtype], serialize_dynamic(msgtype, definition)[msgtype]


def test_the_table_covers_every_field_of_every_supported_type():
    assert sorted((t, f) for t, m in messages.MAPS.items() for f in m.fields) == CASES


@pytest.mark.parametrize("msgtype, field", CASES)
def test_a_built_message_reads_back_the_same_through_a_second_cdr_reader(msgtype, field, typestore):
    message_map = messages.MAPS[msgtype]
    values = _values(message_map.fields[field], CASES.index((msgtype, field)))
    names = JOINTS if message_map.named else ()
    message = message_map.build(typestore.types, STAMP, "base_link", names, {field: values})
    cdr = bytes(typestore.serialize_cdr(message, msgtype))
    decode, _ = _second_reader(msgtype, typestore)
    decoded = decode(cdr)
    got = np.array(INDEPENDENT[msgtype, field](decoded), dtype=np.float64)
    assert got.tobytes() == values.tobytes()
    if message_map.stamped:
        assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == (1_663_502_400, 123_456_789)
        assert decoded.header.frame_id == "base_link"
        assert messages.cdr_stamp(cdr) == STAMP
    if message_map.named:
        assert list(decoded.name if msgtype.endswith("JointState") else decoded.joint_names) == JOINTS


@pytest.mark.parametrize("msgtype, field", CASES)
def test_a_message_written_by_a_second_cdr_writer_reads_as_its_field(msgtype, field, typestore):
    message_map = messages.MAPS[msgtype]
    values = _values(message_map.fields[field], 100 + CASES.index((msgtype, field)))
    _, encode = _second_reader(msgtype, typestore)
    # the same message as the second library writes it (its dict form), every other field left at its default
    built = message_map.build(typestore.types, STAMP, "f", JOINTS if message_map.named else (), {field: values})
    cdr = bytes(encode(_as_dict(built)))
    got = messages.read(message_map, field, typestore.deserialize_cdr(cdr, msgtype), None)
    assert got.tobytes() == values.tobytes()
    if message_map.stamped:
        assert messages.cdr_stamp(cdr) == STAMP


def _as_dict(message):
    """A rosbags message as plain dicts and lists (the second writer's input)."""
    if hasattr(message, "__dataclass_fields__"):
        return {k: _as_dict(getattr(message, k)) for k in message.__dataclass_fields__ if k != "__msgtype__"}
    if isinstance(message, np.ndarray):
        return message.tolist()
    if isinstance(message, list):
        return [_as_dict(m) for m in message]
    return message


def test_joint_values_are_read_by_name_in_the_order_asked(typestore):
    joint_state = messages.MAPS["sensor_msgs/msg/JointState"]
    message = joint_state.build(typestore.types, STAMP, "", JOINTS, {"effort": np.array([1.0, 2.0, 3.0])})
    assert messages.read(joint_state, "effort", message, ["wrist", "shoulder"]).tolist() == [3.0, 1.0]
    with pytest.raises(Exception, match="'hip' is not in the message's joint names"):
        messages.read(joint_state, "effort", message, ["hip"])


def test_parts_not_given_are_neutral(typestore):
    imu = messages.MAPS["sensor_msgs/msg/Imu"].build(
        typestore.types, STAMP, "imu", (), {"angular_velocity": np.array([0.1, 0.2, 0.3])}
    )
    assert _xyzw(imu.orientation) == [0.0, 0.0, 0.0, 1.0]
    assert imu.orientation_covariance[0] == -1.0 and imu.linear_acceleration_covariance[0] == -1.0  # REP 145
    assert imu.angular_velocity_covariance[0] == 0.0
    pose = messages.MAPS["geometry_msgs/msg/PoseStamped"].build(
        typestore.types, STAMP, "", (), {"position": np.array([1.0, 2.0, 3.0])}
    )
    assert _xyzw(pose.pose.orientation) == [0.0, 0.0, 0.0, 1.0]


def test_a_float64_multiarray_is_read_after_its_data_offset(typestore):
    types = typestore.types
    layout = types["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=2)
    message = types["std_msgs/msg/Float64MultiArray"](layout=layout, data=np.array([9.0, 9.0, 1.5, 2.5]))
    assert messages.read(messages.MAPS["std_msgs/msg/Float64MultiArray"], "data", message, None).tolist() == [1.5, 2.5]


# ---------------------------------------------------------------------------------- lockstep rules


def test_stamped_takes_the_message_of_the_step_and_drops_older_ones():
    arrivals = lockstep.Arrivals({"/a": True})
    for stamp in (10, 20, 30):
        arrivals.put("/a", stamp, f"m{stamp}")
    assert arrivals.take_stamped(20, 0.0) == {"/a": "m20"}
    assert arrivals.dropped["/a"] == 1  # m10: older than the step
    arrivals.put("/a", 15, "late")  # stamped before the step now waited for
    assert arrivals.dropped["/a"] == 2
    assert arrivals.take_stamped(30, 0.0) == {"/a": "m30"}


def test_stamped_waits_for_a_message_from_another_thread():
    arrivals = lockstep.Arrivals({"/a": True, "/b": False})
    arrivals.put("/b", None, "before")  # not an answer to the step's inputs
    arrivals.expect()
    got = {}
    waiter = threading.Thread(target=lambda: got.update(arrivals.take_stamped(7, 60.0)))
    waiter.start()
    arrivals.put("/a", 7, "a7")
    arrivals.put("/b", None, "answer")
    waiter.join(60.0)
    assert got == {"/a": "a7", "/b": "answer"}
    assert arrivals.dropped == {"/a": 0, "/b": 1}


def test_stamped_times_out_naming_the_topic():
    arrivals = lockstep.Arrivals({"/cmd": True, "/other": False})
    arrivals.put("/cmd", 2_000_000_001, "ahead")
    with pytest.raises(lockstep.Timeout, match=r"no message on /cmd stamped 1\.000000000 .*within 0 s"):
        arrivals.take_stamped(1_000_000_000, 0.0)
    arrivals.put("/cmd", 3_000_000_000, "m")
    with pytest.raises(lockstep.Timeout, match="no message on /other within 0 s"):
        arrivals.take_stamped(3_000_000_000, 0.0)


def test_an_interrupt_ends_a_wait():
    arrivals = lockstep.Arrivals({"/cmd": True})
    failure = []

    def wait():
        try:
            arrivals.take_stamped(5, 3600.0)
        except lockstep.Interrupted as e:
            failure.append(str(e))

    waiter = threading.Thread(target=wait)
    waiter.start()
    arrivals.interrupt()
    waiter.join(60.0)
    assert not waiter.is_alive() and failure == ["the run is ending: stopped waiting for /cmd"]


def test_latest_takes_the_newest_whatever_its_stamp():
    arrivals = lockstep.Arrivals({"/a": True, "/b": False})
    assert arrivals.take_latest() == {}
    arrivals.put("/a", 50, "a50")
    arrivals.put("/a", 40, "a40")
    arrivals.put("/b", None, "b")
    assert arrivals.take_latest() == {"/a": "a40", "/b": "b"}


# ---------------------------------------------------------------------------------- check-time errors


def _errors(outputs=None, inputs=None, **extra) -> dict[str, str]:
    params = {"wait_for": "stamped", "outputs": outputs or {}, "inputs": inputs or {}, **extra}
    _, _, errors = resolve_parameters(Ros2Bridge, params, RunSettings())
    return {e.key: e.message for e in errors}


TAU = {"topic": "/arm/effort", "type": "std_msgs/msg/Float64MultiArray", "size": 2, "unit": "N*m"}
Q = {
    "topic": "/arm/joint_states",
    "type": "sensor_msgs/msg/JointState",
    "field": "position",
    "names": ["j1", "j2"],
    "unit": "rad",
}


def test_a_valid_bridge_declares_its_variables():
    assert _errors({"tau": TAU}, {"q": Q}) == {}
    variables = {
        v.name: v
        for v in Ros2Bridge.declare(
            resolve_parameters(
                Ros2Bridge,
                {
                    "wait_for": "latest",
                    "outputs": {
                        "tau": TAU,
                        "f": {"topic": "/ft", "type": "geometry_msgs/msg/WrenchStamped", "field": "wrench"},
                    },
                    "inputs": {"q": Q},
                },
                RunSettings(),
            )[1],
            RunSettings(),
        )
    }
    assert (variables["tau"].causality, variables["tau"].shape, variables["tau"].unit) == ("output", (2,), "N*m")
    assert (variables["f"].shape, variables["f"].unit) == ((6,), "N, N*m")
    assert (variables["q"].causality, variables["q"].shape) == ("input", (2,))


def test_a_type_the_bridge_cannot_map_names_the_topic_and_the_supported_types():
    errors = _errors({"tau": {**TAU, "type": "nav_msgs/msg/Odometry"}})
    message = errors["outputs.tau.type"]
    assert "topic /arm/effort" in message and "'nav_msgs/msg/Odometry'" in message
    assert all(t in message for t in messages.MAPS)


@pytest.mark.parametrize(
    "topic, why",
    [
        ("arm/effort", "not absolute"),
        ("/arm/2effort", "starts with a digit"),
        ("/arm effort", "contains ' '"),
        ("/arm//effort", "'//'"),
        ("/arm/", "ends with '/'"),
    ],
)
def test_a_topic_name_ros_rejects_is_named(topic, why):
    message = _errors({"tau": {**TAU, "topic": topic}})["outputs.tau.topic"]
    assert repr(topic) in message and why in message


@pytest.mark.parametrize(
    "spec, key, words",
    [
        ({**TAU, "size": None}, "outputs.tau.size", "is a sequence"),
        ({**TAU, "unit": None}, "outputs.tau.unit", "has no unit of its own"),
        ({**TAU, "field": "layout"}, "outputs.tau.field", "expected a field of std_msgs/msg/Float64MultiArray (data)"),
        ({**TAU, "names": ["a", "b"]}, "outputs.tau.names", "carries no joint names"),
        ({**TAU, "topic": "/clock"}, "outputs.tau.topic", "/clock is the bridge's own"),
        ({"topic": "/w", "type": "geometry_msgs/msg/WrenchStamped"}, "outputs.tau.field", "several fields"),
        (
            {"topic": "/w", "type": "geometry_msgs/msg/WrenchStamped", "field": "force", "size": 6},
            "outputs.tau.size",
            "holds 3 values, got size 6",
        ),
        ({**Q, "names": ["j1"], "size": 2}, "outputs.tau.names", "expected 2 joint names"),
    ],
)
def test_a_wrong_output_is_named(spec, key, words):
    errors = _errors({"tau": spec})
    assert key in errors and words in errors[key], errors


def test_variables_of_one_topic_must_agree():
    wrench = {"topic": "/w", "type": "geometry_msgs/msg/WrenchStamped"}
    errors = _errors({"f": {**wrench, "field": "force"}, "w": {**wrench, "field": "wrench"}})
    assert "topic /w: f is its force already" in errors["outputs.w.field"]
    errors = _errors({"tau": TAU, "t2": {**TAU, "type": "std_msgs/msg/Float64", "size": None}})
    assert "is std_msgs/msg/Float64MultiArray (for tau)" in errors["outputs.t2.type"]
    errors = _errors(
        {"tau": TAU},
        {
            "q": {
                **Q,
                "topic": "/arm/effort",
                "type": "std_msgs/msg/Float64MultiArray",
                "field": None,
                "names": None,
                "size": 2,
            }
        },
    )
    assert "/arm/effort is also among the outputs" in errors["inputs.q.topic"]
    errors = _errors({"q": TAU}, {"q": Q})
    assert "unique" in errors["inputs.q"]
    assert "no variable" in _errors()["outputs"]
