"""The ROS 2 side over a real rclpy (``transport: rclpy``), as a stock ROS 2 Jazzy has it: the
community wheels (rclpy on Fast DDS, Jazzy's default middleware) in a venv of their own
(tests/ros2_rclpy/environment.py), never in the project's. The ROS nodes here are real rclpy
nodes in processes of their own, run by that venv's Python; they import only ROS 2's packages.

- The live view (``ros2: {transport: rclpy}``): a subscriber started before the run receives, on
  every topic of the rosbag2 export whose message package has a wheel, the export's messages at the
  rows that went out, byte for byte, in order, none missing; ``/clock`` carries those rows' stamps.
  ``tf2_msgs`` has no wheel: the view says it cannot publish /tf and /tf_static (those topics are
  checked through the rosbag2 reader by tests/integration/test_rosbag_export.py). A late joiner
  gets the latched robot descriptions.
- ``ros2.bridge`` in lockstep with a real rclpy node (a PD law on a spring, ``use_sim_time``): the
  recording equals, bit for bit, the loop stepped in process (tests/integration/test_ros2_bridge.py
  ``reference``), the node's clock read the stamp of each state it answered, and the docs' own node
  (docs/guides/ros2.md) does the same; a node that dies fails the run naming its topic.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from components.rosbag import epoch_ns
from tests.conftest import ROOT, component_processes, orchestrator, wait_until
from tests.integration.test_ros2_bridge import EPOCH, KD, KP, STEP_NS, STEPS, reference

pytestmark = pytest.mark.integration

HERE = ROOT / "tests" / "ros2_rclpy"
CAPTURE = ROOT / "configs" / "capture_tumbling_target.yaml"
WITHOUT_WHEEL = {"tf2_msgs"}  # message packages ROS 2 Jazzy has no PyPI wheel for
# each test its own ROS domain, so that nothing of one test's DDS graph reaches another's, and
# each test session its own five (from its process id), for two sessions on one machine
_BASE = 10 + 5 * (os.getpid() % 40)  # Fast DDS takes domain ids up to 232
DOMAIN_VIEW, DOMAIN_LATE, DOMAIN_BRIDGE, DOMAIN_DOCS, DOMAIN_DIES = range(_BASE, _BASE + 5)


@pytest.fixture(scope="session")
def ros_python() -> str:
    from tests.ros2_rclpy.environment import ensure

    try:
        return str(ensure())
    except (RuntimeError, OSError, subprocess.SubprocessError) as e:
        pytest.skip(f"no ROS 2 Jazzy wheels here: {e}")


class RosProcess:
    """A script of tests/ros2_rclpy (or any file) run by the ROS venv's Python; stopped by :meth:`stop`."""

    def __init__(self, python: str, script: Path, tmp: Path, name: str, *args: str, ready: bool = True):
        self.ready = tmp / f"{name}.ready"
        self.log_path = tmp / f"{name}.log"
        self.log = open(self.log_path, "w")  # noqa: SIM115 (the process writes it; stop() closes it)
        extra = ["--ready", str(self.ready)] if ready else []
        self.process = subprocess.Popen(
            [python, str(script), *args, *extra],
            stdin=subprocess.PIPE,
            stdout=self.log,
            stderr=subprocess.STDOUT,
            cwd=tmp,
        )
        if ready:
            wait_until(lambda: self.ready.exists() or self.process.poll() is not None, f"{name} ready", 120)
            assert self.process.poll() is None, self.log_path.read_text()

    def finish(self, timeout: float = 60) -> int:
        """Close its stdin (the listener writes what it got and exits) and wait."""
        self.process.stdin.close()
        code = self.process.wait(timeout)
        self.log.close()
        return code

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if not self.log.closed:
            self.log.close()


@pytest.fixture
def ros(tmp_path, ros_python):
    started: list[RosProcess] = []

    def start(script: Path, name: str, *args: str, ready: bool = True) -> RosProcess:
        process = RosProcess(ros_python, script, tmp_path, name, *args, ready=ready)
        started.append(process)
        return process

    yield start
    for process in started:
        process.stop()


def export_messages(record: Path, bag: Path) -> dict[str, tuple[str, list[tuple[int, bytes]]]]:
    """{topic: (type, [(log time ns, CDR)])} of the recording's rosbag2 export, read with ``mcap``."""
    from mcap.reader import make_reader

    result = orchestrator("export", record, "--rosbag2", bag)
    assert result.returncode == 0, result.stdout + result.stderr
    topics: dict[str, tuple[str, list]] = {}
    with open(next(bag.glob("*.mcap")), "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            topics.setdefault(channel.topic, (schema.name, []))[1].append((message.log_time, bytes(message.data)))
    return topics


def received(path: Path) -> dict[str, list[bytes]]:
    got: dict[str, list[bytes]] = {}
    for line in path.read_text().splitlines():
        entry = json.loads(line)
        got.setdefault(entry["topic"], []).append(bytes.fromhex(entry["cdr"]))
    return got


def dds_padded(cdr: bytes) -> bytes:
    """A serialized message as a DDS reader gets it: Fast DDS pads the payload with zeros to a
    multiple of 4 bytes (the message it decodes to is the same)."""
    return cdr + bytes(-len(cdr) % 4)


def clock_ns(cdr: bytes) -> int:
    """rosgraph_msgs/Clock's CDR (4-byte encapsulation, int32 sec, uint32 nanosec), decoded here."""
    assert cdr[:4] == b"\x00\x01\x00\x00", cdr[:4]
    sec, nanosec = np.frombuffer(cdr[4:12], dtype="<i4")[0], np.frombuffer(cdr[8:12], dtype="<u4")[0]
    return int(sec) * 1_000_000_000 + int(nanosec)


def capture_run(ros_python: str, domain: int, duration: str, realtime: float = 0) -> list[str]:
    """The arguments of ``orchestrator run`` for the capture scenario published with rclpy, every row."""
    return [
        str(CAPTURE),
        "--set",
        f"run.duration={duration}",
        "--set",
        f"run.realtime={realtime}",
        "--set",
        "ros2.transport=rclpy",
        "--set",
        f"ros2.python={ros_python}",
        "--set",
        f"ros2.domain_id={domain}",
        "--set",
        "ros2.rate=100 Hz",
    ]


def listener_args(topics: dict[str, str], latched: set[str], domain: int, out: Path) -> list[str]:
    args = ["--domain", str(domain), "--out", str(out)]
    for topic, msgtype in topics.items():
        args += ["--topic", f"{topic}={msgtype}"]
    for topic in latched:
        args += ["--latched", topic]
    return args


# The capture scenario's topics (its rosbag2 export has these and /tf, /tf_static); the test
# checks this list against the export, so a topic added to the scenario fails it here.
CAPTURE_TOPICS = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/dynamics/servicer/robot_description": "std_msgs/msg/String",
    "/dynamics/servicer/pose": "geometry_msgs/msg/PoseStamped",
    "/dynamics/servicer/twist": "geometry_msgs/msg/TwistStamped",
    "/dynamics/servicer/joint_states": "sensor_msgs/msg/JointState",
    "/dynamics/target/robot_description": "std_msgs/msg/String",
    "/dynamics/target/pose": "geometry_msgs/msg/PoseStamped",
    "/dynamics/target/twist": "geometry_msgs/msg/TwistStamped",
    "/pose_sensor/pose": "geometry_msgs/msg/PoseStamped",
    "/imu/imu": "sensor_msgs/msg/Imu",
    "/wrist_ft/wrench": "geometry_msgs/msg/WrenchStamped",
}
LATCHED = {"/dynamics/servicer/robot_description", "/dynamics/target/robot_description"}


def test_a_stock_ros2_subscriber_receives_every_topic_of_the_export(tmp_path, write_config, ros, ros_python):
    out = tmp_path / "listener.jsonl"
    listener = ros(HERE / "listener.py", "listener", *listener_args(CAPTURE_TOPICS, LATCHED, DOMAIN_VIEW, out))
    record = tmp_path / "rec"
    result = orchestrator("run", *capture_run(ros_python, DOMAIN_VIEW, "2 s"), "--record", record)
    assert result.returncode == 0, result.stdout + result.stderr
    assert listener.finish() == 0, listener.log_path.read_text()
    assert "with rclpy as node /zenorbit_capture_tumbling_target" in result.stderr, result.stderr
    assert "rmw_fastrtps_cpp" in result.stderr, result.stderr

    export = export_messages(record, tmp_path / "bag")
    with_wheel = {t for t, (msgtype, _) in export.items() if msgtype.split("/")[0] not in WITHOUT_WHEEL}
    assert with_wheel == set(CAPTURE_TOPICS)
    for topic in sorted(set(export) - with_wheel):  # said, not silently missing
        assert f"{topic}: no message type {export[topic][0]} in this ROS 2 environment" in result.stderr

    got = received(out)
    stamps = [clock_ns(cdr) for cdr in got["/clock"]]
    rows = [ns for ns, _ in export["/clock"][1]]
    assert stamps == rows, f"{len(stamps)} of {len(rows)} rows reached ROS"  # all, in order
    for topic in sorted(with_wheel):
        msgtype, messages = export[topic]
        expected = [dds_padded(messages[0][1])] if topic in LATCHED else [dds_padded(cdr) for _, cdr in messages]
        assert got.get(topic, []) == expected, (
            f"{topic} ({msgtype}): {len(got.get(topic, []))} received, {len(expected)} expected"
        )
    assert not component_processes("capture_tumbling_target")


def test_a_late_joiner_gets_the_latched_topics(tmp_path, write_config, ros, ros_python):
    early_out, late_out = tmp_path / "early.jsonl", tmp_path / "late.jsonl"
    clock = {"/clock": CAPTURE_TOPICS["/clock"]}
    early = ros(
        HERE / "listener.py",
        "early",
        *listener_args(clock, set(), DOMAIN_LATE, early_out),
        "--first",
        str(tmp_path / "first"),
    )
    record = tmp_path / "rec"
    # paced at wall time and long: it goes on until the late joiner has what it asks for, then Ctrl-C
    run = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "orchestrator.cli",
            "run",
            *capture_run(ros_python, DOMAIN_LATE, "120 s", realtime=1),
            "--record",
            str(record),
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        wait_until(lambda: (tmp_path / "first").exists(), "the run's first /clock in ROS", 180, run=run)
        late_topics = {t: CAPTURE_TOPICS[t] for t in LATCHED}
        late = ros(
            HERE / "listener.py", "late", *listener_args(late_topics, LATCHED, DOMAIN_LATE, late_out), "--until-all"
        )
        assert late.process.wait(120) == 0, late.log_path.read_text()
        assert run.poll() is None, "the run ended before the late joiner had the latched topics"
        run.send_signal(signal.SIGINT)
        out, err = run.communicate(timeout=120)
        assert run.returncode == 130, out + err
    finally:
        if run.poll() is None:
            run.kill()
            run.communicate()
    assert early.finish() == 0
    export = export_messages(record, tmp_path / "bag")
    got = received(late_out)
    for topic in LATCHED:
        assert got[topic] == [dds_padded(export[topic][1][0][1])], topic
    assert not component_processes("capture_tumbling_target")


def bridge_config(
    name: str, ros_python: str, domain: int, outputs: str, timeout: str = "30 s", steps: int = STEPS
) -> str:
    return f"""
run: {{name: {name}, epoch: {EPOCH}, duration: {steps * STEP_NS // 1_000_000} ms, step: 10 ms, step_timeout: 60 s}}
components:
  spring:
    type: components.examples.oscillator:Oscillator
    parameters: {{mass: 2 kg, stiffness: 8 N/m, x0: 1 m}}
  node:
    type: ros2.bridge
    parameters:
      wait_for: stamped
      transport: rclpy
      python: {ros_python}
      domain_id: {domain}
      timeout: {timeout}
      inputs:
        x: {{topic: /spring/joint_states, type: sensor_msgs/msg/JointState, field: position, names: [slide], unit: m}}
        v: {{topic: /spring/joint_states, type: sensor_msgs/msg/JointState, field: velocity, names: [slide], unit: m/s}}
      outputs:
{outputs}
connections:
  spring.force: node.force
  node.x: spring.x
  node.v: spring.v
"""


BOTH_OUTPUTS = """\
        force: {topic: /spring/effort, type: trajectory_msgs/msg/JointTrajectory, field: effort, names: [slide], unit: N}
        force_array: {topic: /spring/effort_array, type: std_msgs/msg/Float64MultiArray, size: 1, unit: N}"""


def test_bridge_in_lockstep_with_an_rclpy_node_equals_the_loop_in_process(tmp_path, write_config, ros, ros_python):
    import pandas as pd

    log = tmp_path / "answers.log"
    node = ros(
        HERE / "spring_node.py",
        "spring",
        "--domain",
        str(DOMAIN_BRIDGE),
        "--kp",
        str(KP),
        "--kd",
        str(KD),
        "--log",
        str(log),
    )
    record = tmp_path / "rec"
    result = orchestrator(
        "run", write_config(bridge_config("rclpy_pd", ros_python, DOMAIN_BRIDGE, BOTH_OUTPUTS)), "--record", record
    )
    assert result.returncode == 0, result.stdout + result.stderr
    node.stop()
    assert "transport: rclpy" in (record / "logs" / "node.0.log").read_text()
    signals = pd.read_parquet(record / "signals.parquet")
    assert len(signals) == STEPS + 1
    expected = reference(STEPS)
    for column, values in expected.items():
        got = signals[column].to_numpy()
        assert got.tobytes() == values.tobytes(), (
            f"{column}: first difference at row {int(np.flatnonzero(got != values)[0])}"
        )
    assert signals["node.force_array[0]"].to_numpy().tobytes() == expected["node.force[0]"].tobytes()
    assert np.ptp(expected["node.force[0]"]) > 1.0  # the PD law did act
    # use_sim_time: the node's clock, when it answered step k, read t_k exactly (the run's /clock)
    answers = [tuple(map(int, line.split())) for line in log.read_text().splitlines()]
    assert [stamp for stamp, _ in answers] == [epoch_ns(EPOCH) + k * STEP_NS for k in range(STEPS)]
    assert all(now == stamp for stamp, now in answers), [a for a in answers if a[0] != a[1]][:3]
    assert not component_processes("rclpy_pd")


def test_the_docs_node_drives_the_docs_bridge(tmp_path, write_config, ros, ros_python):
    import pandas as pd

    guide = (ROOT / "docs" / "guides" / "ros2.md").read_text()
    source = next(block for block in guide.split("```python\n")[1:] if "class PD(Node)" in block).split("```")[0]
    (tmp_path / "pd.py").write_text(source)
    # the guide's own command line (ROS_DOMAIN_ID in its environment: a user's shell)
    env_domain = {"ROS_DOMAIN_ID": str(DOMAIN_DOCS)}
    node = subprocess.Popen(
        [ros_python, str(tmp_path / "pd.py"), "--ros-args", "-p", "use_sim_time:=true"],
        env={**os.environ, **env_domain},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        outputs = BOTH_OUTPUTS.splitlines()[0]  # the guide's node answers on one topic
        text = bridge_config("rclpy_docs", ros_python, DOMAIN_DOCS, outputs)
        record = tmp_path / "rec"
        result = orchestrator("run", write_config(text), "--record", record)  # waits for the node's topics
        assert result.returncode == 0, result.stdout + result.stderr
    finally:
        node.terminate()
        try:
            node.wait(30)
        except subprocess.TimeoutExpired:  # a loaded machine: never leave the node behind
            node.kill()
            node.wait()
    signals = pd.read_parquet(record / "signals.parquet")
    for column, values in reference(STEPS).items():
        assert signals[column].to_numpy().tobytes() == values.tobytes(), column


def test_a_node_that_dies_fails_the_run_naming_its_topic(tmp_path, write_config, ros, ros_python):
    import pandas as pd

    last = 40
    ros(
        HERE / "spring_node.py",
        "spring",
        "--domain",
        str(DOMAIN_DIES),
        "--kp",
        str(KP),
        "--kd",
        str(KD),
        "--log",
        str(tmp_path / "answers.log"),
        "--exit-after",
        str(last + 1),
    )
    record = tmp_path / "rec"
    text = bridge_config("rclpy_dies", ros_python, DOMAIN_DIES, BOTH_OUTPUTS, timeout="3 s")
    result = orchestrator("run", write_config(text), "--record", record)
    out = result.stdout + result.stderr
    assert result.returncode == 1, out
    t = epoch_ns(EPOCH) + (last + 1) * STEP_NS
    assert f"no message on /spring/effort stamped {t // 10**9}.{t % 10**9:09d}" in out, out
    assert len(pd.read_parquet(record / "signals.parquet")) == last + 2
    assert not component_processes("rclpy_dies")


def test_rclpy_asked_for_without_it_is_refused_at_check(write_config):
    path = write_config(
        bridge_config("rclpy_none", "/usr/bin/env", 0, BOTH_OUTPUTS).replace(
            "python: /usr/bin/env", f"python: {sys.executable}"
        )
    )
    result = orchestrator("check", path)
    assert result.returncode == 2, result.stdout + result.stderr
    assert "transport rclpy: no Python here imports rclpy" in result.stderr, result.stderr
    assert "No module named 'rclpy'" in result.stderr, result.stderr
