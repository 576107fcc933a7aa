"""`orchestrator export DIR --rosbag2 OUT` as a user runs it: the demo and the capture scenario,
recorded once each, exported, and read back with a second, independent reader (`mcap` with
`mcap-ros2-support`, not rosbags) against signals.parquet bit for bit; metadata.yaml; bad input."""

from __future__ import annotations

import shutil
from datetime import UTC, datetime

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from tests.conftest import ROOT, orchestrator

pytestmark = pytest.mark.integration


def _record(tmp_path_factory, config: str, *sets: str):
    record = tmp_path_factory.mktemp(config) / "rec"
    overrides = [a for s in sets for a in ("--set", s)]
    result = orchestrator("run", ROOT / "configs" / f"{config}.yaml", "--record", record, *overrides)
    assert result.returncode == 0, result.stderr
    return record


def _export(record, bag):
    result = orchestrator("export", record, "--rosbag2", bag)
    assert result.returncode == 0, result.stderr
    return result


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """configs/humanoid_tracking.yaml, 1 s at 1 ms, recorded and exported."""
    record = _record(tmp_path_factory, "humanoid_tracking", "run.duration=1 s")
    bag = record.parent / "bag"
    return record, bag, _export(record, bag)


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """configs/capture_tumbling_target.yaml, 1 s at 10 ms, with the link poses recorded, exported."""
    record = _record(
        tmp_path_factory,
        "capture_tumbling_target",
        "run.duration=1 s",
        "components.dynamics.parameters.link_outputs=true",
    )
    bag = record.parent / "bag"
    return record, bag, _export(record, bag)


def _read(bag) -> dict[str, list]:
    """{topic: [(log time ns, decoded message)]} with the independent reader."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    (path,) = bag.glob("*.mcap")
    topics: dict[str, list] = {}
    with open(path, "rb") as f:
        for _, channel, message, decoded in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
            log_time_order=True
        ):
            topics.setdefault(channel.topic, []).append((message.log_time, decoded))
    return topics


def _parquet(record) -> dict[str, np.ndarray]:
    table = pq.read_table(record / "signals.parquet")
    return {name: table.column(name).to_numpy() for name in table.column_names}


def _vector(columns, name, n):
    return np.column_stack([columns[f"{name}[{i}]"] for i in range(n)])


def _stamps(record, columns) -> np.ndarray:
    epoch = yaml.safe_load((record / "config.yaml").read_text())["run"]["epoch"]
    start = datetime.fromisoformat(str(epoch).replace("Z", "+00:00")) - datetime(1970, 1, 1, tzinfo=UTC)
    return int(start.total_seconds()) * 1_000_000_000 + np.rint(columns["time"] * 1e9).astype(np.int64)


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def _xyz(v):
    return [v.x, v.y, v.z]


def _xyzw(q):
    return [q.x, q.y, q.z, q.w]


def _equal(a, b):
    """Bit for bit: float64 values equal (and the same NaNs)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    assert a.shape == b.shape and a.tobytes() == b.tobytes(), f"{a} != {b}"


def _tf_by_child(messages) -> dict[str, list]:
    by_child: dict[str, list] = {}
    for _, message in messages:
        for t in message.transforms:
            by_child.setdefault(t.child_frame_id, []).append(t)
    return by_child


def test_the_demo_exports_clock_tf_joint_states_pose_and_twist_bit_for_bit(demo):
    record, bag, result = demo
    columns, topics = _parquet(record), _read(bag)
    stamps = _stamps(record, columns)
    n = len(stamps)
    assert [log for log, _ in topics["/clock"]] == list(stamps)
    assert [_ns(m.clock) for _, m in topics["/clock"]] == list(stamps)

    position = _vector(columns, "dynamics.humanoid.position", 3)
    orientation = _vector(columns, "dynamics.humanoid.orientation", 4)
    twist = _vector(columns, "dynamics.humanoid.twist", 6)
    q, qd = _vector(columns, "dynamics.humanoid.q", 14), _vector(columns, "dynamics.humanoid.qd", 14)
    tau = _vector(columns, "controller.tau", 14)
    poses, twists = topics["/dynamics/humanoid/pose"], topics["/dynamics/humanoid/twist"]
    joints = topics["/dynamics/humanoid/joint_states"]
    assert len(poses) == len(twists) == len(joints) == n
    _equal([_xyz(m.pose.position) for _, m in poses], position)
    _equal([_xyzw(m.pose.orientation) for _, m in poses], orientation)
    _equal([_xyz(m.twist.linear) + _xyz(m.twist.angular) for _, m in twists], twist)
    _equal([m.position for _, m in joints], q)
    _equal([m.velocity for _, m in joints], qd)
    _equal([m.effort for _, m in joints], tau)
    assert joints[0][1].name[0] == "arm_left_1_joint" and len(joints[0][1].name) == 14
    for topic in (poses, twists, joints):
        assert [_ns(m.header.stamp) for _, m in topic] == list(stamps) == [log for log, _ in topic]
    assert {m.header.frame_id for _, m in poses + twists} == {"dynamics/world"}

    tf = _tf_by_child(topics["/tf"])
    lvlh = tf["orbit/lvlh"]
    _equal([_xyz(t.transform.translation) for t in lvlh], _vector(columns, "orbit.r_eci", 3))
    _equal([_xyzw(t.transform.rotation) for t in lvlh], _vector(columns, "orbit.q_eci_lvlh", 4))
    _equal([_xyz(t.transform.translation) for t in tf["dynamics/world"]], _vector(columns, "orbit.r_eci", 3))
    assert {t.header.frame_id for t in lvlh + tf["dynamics/world"]} == {"eci"}
    links = [child for child in tf if child.startswith("dynamics/humanoid/")]
    assert len(links) > 10 and all(len(tf[c]) == n for c in links)  # every link, forward kinematics
    from components.robots.urdf import read_urdf

    model = read_urdf(ROOT / "models" / "humanoid_torso.urdf")
    assert set(links) == {f"dynamics/humanoid/{link}" for link in model.link_names}
    base = tf[f"dynamics/humanoid/{model.root}"]
    _equal([_xyz(t.transform.translation) for t in base], position)
    _equal([_xyzw(t.transform.rotation) for t in base], orientation)
    description = topics["/dynamics/humanoid/robot_description"]
    assert len(description) == 1 and description[0][1].data.lstrip().startswith("<")
    assert "controller.computed_torque declares no ROS messages" in result.stderr


def test_the_capture_exports_sensors_links_and_static_mounts_bit_for_bit(capture):
    record, bag, _ = capture
    columns, topics = _parquet(record), _read(bag)
    stamps = _stamps(record, columns)
    imu = topics["/imu/imu"]
    _equal([_xyz(m.angular_velocity) for _, m in imu], _vector(columns, "imu.rate", 3))
    _equal([_xyz(m.linear_acceleration) for _, m in imu], _vector(columns, "imu.specific_force", 3))
    assert imu[0][1].orientation_covariance[0] == -1 and {m.header.frame_id for _, m in imu} == {"imu"}
    wrench = topics["/wrist_ft/wrench"]
    _equal([_xyz(m.wrench.force) + _xyz(m.wrench.torque) for _, m in wrench], _vector(columns, "wrist_ft.wrench", 6))
    assert [log for log, _ in wrench] == list(stamps)

    # relative pose: once per measurement, stamped when it was taken, logged when it came out
    valid, t_measured = columns["pose_sensor.valid"], columns["pose_sensor.t_measured"]
    rows = [
        r for r in range(len(valid)) if valid[r] and (r == 0 or not valid[r - 1] or t_measured[r] != t_measured[r - 1])
    ]
    pose = topics["/pose_sensor/pose"]
    assert len(pose) == len(rows) > 5
    _equal([_xyz(m.pose.position) for _, m in pose], _vector(columns, "pose_sensor.p", 3)[rows])
    _equal([_xyzw(m.pose.orientation) for _, m in pose], _vector(columns, "pose_sensor.q", 4)[rows])
    assert [log for log, _ in pose] == list(stamps[rows])
    epoch = stamps[0] - int(np.rint(columns["time"][0] * 1e9))
    assert [_ns(m.header.stamp) for _, m in pose] == [epoch + int(np.rint(t * 1e9)) for t in t_measured[rows]]

    # every link as recorded (link_outputs: true), in W; the base as position and orientation
    from components.robots.urdf import read_urdf

    model = read_urdf(ROOT / "models" / "capture" / "servicer.urdf")
    n, m = len(stamps), len(model.link_names)
    link_position = _vector(columns, "dynamics.servicer.link_position", 3 * m).reshape(n, m, 3)
    link_orientation = _vector(columns, "dynamics.servicer.link_orientation", 4 * m).reshape(n, m, 4)
    tf = _tf_by_child(topics["/tf"])
    assert {c for c in tf if c.startswith("dynamics/servicer/")} == {
        f"dynamics/servicer/{link}" for link in model.link_names
    }
    for j, link in enumerate(model.link_names):
        transforms = tf[f"dynamics/servicer/{link}"]
        assert {t.header.frame_id for t in transforms} == {"dynamics/world"} and len(transforms) == n
        if link == model.root:
            expected = (
                _vector(columns, "dynamics.servicer.position", 3),
                _vector(columns, "dynamics.servicer.orientation", 4),
            )
        else:
            expected = link_position[:, j], link_orientation[:, j]
        _equal([_xyz(t.transform.translation) for t in transforms], expected[0])
        _equal([_xyzw(t.transform.rotation) for t in transforms], expected[1])
    ee = yaml.safe_load((record / "config.yaml").read_text())["components"]["dynamics"]["parameters"]["grasp"][
        "end_effector"
    ]
    static = topics["/tf_static"]
    assert len(static) == 1
    mounts = {t.child_frame_id: t.header.frame_id for t in static[0][1].transforms}
    assert mounts["pose_sensor"] == mounts["wrist_ft"] == f"dynamics/servicer/{ee}"
    assert mounts["imu"].startswith("dynamics/servicer/")


def test_metadata_names_the_topics_types_counts_storage_and_latched_qos(capture):
    record, bag, _ = capture
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["storage_identifier"] == "mcap" and info["version"] == 9
    assert info["ros_distro"] == "jazzy"  # the types' distro, as rosbag2 writes it (rosbags wrote "rosbags")
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    rows = pq.read_table(record / "signals.parquet", columns=["time"]).num_rows
    expected = {
        "/clock": "rosgraph_msgs/msg/Clock",
        "/tf": "tf2_msgs/msg/TFMessage",
        "/tf_static": "tf2_msgs/msg/TFMessage",
        "/imu/imu": "sensor_msgs/msg/Imu",
        "/wrist_ft/wrench": "geometry_msgs/msg/WrenchStamped",
        "/pose_sensor/pose": "geometry_msgs/msg/PoseStamped",
        "/dynamics/servicer/joint_states": "sensor_msgs/msg/JointState",
        "/dynamics/servicer/pose": "geometry_msgs/msg/PoseStamped",
        "/dynamics/servicer/twist": "geometry_msgs/msg/TwistStamped",
        "/dynamics/servicer/robot_description": "std_msgs/msg/String",
        "/dynamics/target/robot_description": "std_msgs/msg/String",
    }
    for name, msgtype in expected.items():
        assert topics[name]["topic_metadata"]["type"] == msgtype
        assert topics[name]["topic_metadata"]["type_description_hash"].startswith("RIHS01_")
    assert topics["/clock"]["message_count"] == topics["/imu/imu"]["message_count"] == rows
    assert info["message_count"] == sum(t["message_count"] for t in topics.values())
    for name, durability in (
        ("/tf_static", "transient_local"),
        ("/dynamics/servicer/robot_description", "transient_local"),
        ("/tf", "volatile"),
    ):
        qos = (
            yaml.safe_load(topics[name]["topic_metadata"]["offered_qos_profiles"])
            if isinstance(topics[name]["topic_metadata"]["offered_qos_profiles"], str)
            else topics[name]["topic_metadata"]["offered_qos_profiles"]
        )
        assert qos[0]["durability"] == durability and qos[0]["reliability"] == "reliable"


def test_an_existing_out_is_refused_unless_overwrite_and_kept_when_refused(capture, tmp_path):
    record, bag, _ = capture
    out = tmp_path / "bag"
    out.mkdir()
    (out / "mine.txt").write_text("keep me")
    result = orchestrator("export", record, "--rosbag2", out)
    assert result.returncode == 2 and "--overwrite" in result.stderr and (out / "mine.txt").exists()
    result = orchestrator("export", record, "--rosbag2", out, "--overwrite")  # not a bag: not touched
    assert result.returncode == 2 and "metadata.yaml" in result.stderr and (out / "mine.txt").exists()
    copy = tmp_path / "copy"
    shutil.copytree(bag, copy)
    result = orchestrator("export", record, "--rosbag2", copy, "--overwrite")
    assert result.returncode == 0, result.stderr
    assert (copy / "metadata.yaml").exists() and not list(tmp_path.glob(".copy.*"))


def test_not_a_recording_is_refused_with_exit_2(tmp_path):
    result = orchestrator("export", tmp_path, "--rosbag2", tmp_path / "bag")
    assert result.returncode == 2
    assert "signals.parquet not found" in result.stderr and "orchestrator run --record" in result.stderr
    assert not (tmp_path / "bag").exists()


def test_a_recording_cut_short_exports_the_rows_it_has(capture, tmp_path):
    record, _, _ = capture
    short = tmp_path / "short"
    short.mkdir()
    shutil.copy(record / "config.yaml", short / "config.yaml")
    table = pq.read_table(record / "signals.parquet")
    (short / "signals.parquet").mkdir()  # a dataset directory, as the run writes it, stopped at row 37
    pq.write_table(table.slice(0, 37), short / "signals.parquet" / "part-000000.parquet")
    result = orchestrator("export", short, "--rosbag2", tmp_path / "bag")
    assert result.returncode == 0, result.stderr
    topics = _read(tmp_path / "bag")
    assert len(topics["/clock"]) == len(topics["/imu/imu"]) == 37


def test_all_signals_exports_a_type_without_ros_messages_as_arrays(capture, tmp_path):
    record, _, _ = capture
    result = orchestrator("export", record, "--rosbag2", tmp_path / "bag", "--all-signals")
    assert result.returncode == 0, result.stderr
    assert "declares no ROS messages" not in result.stderr
    columns, topics = _parquet(record), _read(tmp_path / "bag")
    m = sum(1 for c in columns if c.startswith("controller.tau["))
    tau = topics["/controller/tau"]
    _equal([message.data for _, message in tau], _vector(columns, "controller.tau", m))
    _equal([message.data for _, message in topics["/controller/phase"]], columns["controller.phase"][:, None])
    assert [log for log, _ in tau] == list(_stamps(record, columns))
