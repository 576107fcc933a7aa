"""``ros2.bridge`` in a real run (the orchestrator and each component a process, Zenoh on loopback)
against a stand-in ROS 2 node (tests/integration/ros2_standin.py, a Zenoh program of its own that
follows rmw_zenoh's conventions): a mass on a spring whose force is a PD law computed by the node.

- ``wait_for: stamped``: the recorded run equals, bit for bit, the same loop stepped in process
  (the oscillator in the harness, the PD law in Python, its answer applied a step later as any
  controller's under Jacobi), through both the stamped rule (JointTrajectory) and the answer rule
  of a type without a header (Float64MultiArray); the node saw /clock at every step's time.
- The node stops answering: the run fails, naming the topic, at the step it stopped at, and leaves
  no process behind.
- ``wait_for: latest``: every output is the node's answer to an earlier step (or the start value),
  each newer than the one before; which one depends on timing (not deterministic).
- No router at the endpoint, or no node on a topic: the run fails at its start, naming them.
- A run stopped (Ctrl-C) while the bridge waits: the bridge's wait is interrupted, so it ends by
  itself rather than being killed after the orchestrator's grace period.
"""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from components.rosbag import epoch_ns
from components.testing.harness import Harness
from tests.conftest import ROOT, component_processes, orchestrator, start_run, wait_until

pytestmark = pytest.mark.integration

EPOCH = "2022-09-18T12:00:00Z"
STEP_NS = 10_000_000
STEPS = 150
KP, KD = 3.0, 0.5
MASS, STIFFNESS, X0 = 2.0, 8.0, 1.0
STANDIN = Path(__file__).with_name("ros2_standin.py")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def config(
    name: str,
    port: int,
    timeout: str = "20 s",
    step_timeout: str = "60 s",
    steps: int = STEPS,
    wait_for: str = "stamped",
    realtime: float = 0,
) -> str:
    return f"""
run: {{name: {name}, epoch: {EPOCH}, duration: {steps * STEP_NS // 1_000_000} ms, step: 10 ms,
       step_timeout: {step_timeout}, realtime: {realtime}}}
components:
  spring:
    type: components.examples.oscillator:Oscillator
    parameters: {{mass: {MASS} kg, stiffness: {STIFFNESS} N/m, x0: {X0} m}}
  node:
    type: ros2.bridge
    parameters:
      wait_for: {wait_for}
      transport: zenoh
      endpoint: tcp/127.0.0.1:{port}
      domain_id: 0
      timeout: {timeout}
      inputs:
        x: {{topic: /spring/joint_states, type: sensor_msgs/msg/JointState, field: position, names: [slide], unit: m}}
        v: {{topic: /spring/joint_states, type: sensor_msgs/msg/JointState, field: velocity, names: [slide], unit: m/s}}
      outputs:
        force: {{topic: /spring/effort, type: trajectory_msgs/msg/JointTrajectory, field: effort, names: [slide],
                 unit: N}}
        force_array: {{topic: /spring/effort_array, type: std_msgs/msg/Float64MultiArray, size: 1, unit: N}}
connections:
  spring.force: node.force
  node.x: spring.x
  node.v: spring.v
"""


class StandIn:
    """The stand-in node as a subprocess, stopped (SIGTERM, then killed) by :meth:`stop`."""

    def __init__(self, tmp: Path, port: int, *extra: str):
        self.ready, self.waiting, self.clock_log = tmp / "standin.ready", tmp / "standin.waiting", tmp / "clock.log"
        self.log = open(tmp / "standin.log", "w")  # noqa: SIM115 (the process writes it; stop() closes it)
        self.process = subprocess.Popen(
            [
                sys.executable,
                str(STANDIN),
                "--listen",
                f"tcp/127.0.0.1:{port}",
                "--kp",
                str(KP),
                "--kd",
                str(KD),
                "--ready",
                str(self.ready),
                "--waiting",
                str(self.waiting),
                "--clock-log",
                str(self.clock_log),
                *extra,
            ],
            cwd=ROOT,
            stdout=self.log,
            stderr=subprocess.STDOUT,
        )
        wait_until(lambda: self.ready.exists() or self.process.poll() is not None, "the stand-in node ready", 60)
        assert self.process.poll() is None, (tmp / "standin.log").read_text()

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.log.close()

    def clocks(self) -> list[int]:
        return [int(line) for line in self.clock_log.read_text().split()]


@pytest.fixture
def standin(tmp_path):
    started = []

    def start(port: int, *extra: str) -> StandIn:
        node = StandIn(tmp_path, port, *extra)
        started.append(node)
        return node

    yield start
    for node in started:
        node.stop()


def reference(steps: int) -> dict[str, np.ndarray]:
    """The loop stepped in process: row k holds the spring at t_k and the force the bridge outputs at
    t_k, the node's answer to the spring at t_{k-1} (0 at t0, the output's start)."""
    spring = Harness("components.examples.oscillator:Oscillator", {"mass": MASS, "stiffness": STIFFNESS, "x0": X0})
    xs, vs, forces = [spring.outputs["x"]], [spring.outputs["v"]], [0.0]
    for _ in range(steps):
        x, v, force = xs[-1], vs[-1], forces[-1]
        spring.inputs["force"] = force
        spring.step(STEP_NS)
        forces.append(-KP * np.array([x]) - KD * np.array([v]))  # the node's expression, on float64 arrays
        xs.append(spring.outputs["x"])
        vs.append(spring.outputs["v"])
    return {
        "spring.x": np.array(xs, dtype=np.float64).ravel(),
        "spring.v": np.array(vs, dtype=np.float64).ravel(),
        "node.force[0]": np.array([np.ravel(f)[0] for f in forces], dtype=np.float64),
    }


def test_stamped_lockstep_equals_the_loop_in_process(tmp_path, write_config, standin):
    import pandas as pd

    port = _free_port()
    node = standin(port)
    record = tmp_path / "rec"
    result = orchestrator("run", write_config(config("ros2_bridge_pd", port)), "--record", record)
    assert result.returncode == 0, result.stdout + result.stderr
    node.stop()
    signals = pd.read_parquet(record / "signals.parquet")
    assert len(signals) == STEPS + 1
    expected = reference(STEPS)
    for column, values in expected.items():
        got = signals[column].to_numpy()
        assert got.tobytes() == values.tobytes(), (
            f"{column}: first difference at row {int(np.flatnonzero(got != values)[0])}"
        )
    # the answer rule (no header) gives the same numbers as the stamped one
    assert signals["node.force_array[0]"].to_numpy().tobytes() == expected["node.force[0]"].tobytes()
    assert np.ptp(expected["node.force[0]"]) > 1.0  # the PD law did act
    # /clock: the run's time at initialize and at each step, as ROS time (run.epoch + t)
    assert sorted(set(node.clocks())) == [epoch_ns(EPOCH) + k * STEP_NS for k in range(STEPS)]
    assert not component_processes("ros2_bridge_pd")


def test_latest_takes_answers_to_earlier_steps(tmp_path, write_config, standin):
    import pandas as pd

    port = _free_port()
    node = standin(port)
    record = tmp_path / "rec"
    # paced at the wall clock (10 ms a step), so that the node's answers arrive while the run goes on
    result = orchestrator(
        "run", write_config(config("ros2_bridge_latest", port, wait_for="latest", realtime=1)), "--record", record
    )
    assert result.returncode == 0, result.stdout + result.stderr
    node.stop()
    signals = pd.read_parquet(record / "signals.parquet")
    x, v = signals["spring.x"].to_numpy(), signals["spring.v"].to_numpy()
    answers = -KP * x - KD * v  # the node's answer to the inputs of each row
    answered = []  # the row each output answers (-1: the start value)
    for row, force in enumerate(signals["node.force[0]"].to_numpy()):
        earlier = [j for j in range(row) if answers[j] == force]
        if not earlier:  # the start value, until the first answer arrives
            assert force == 0.0 and set(answered) <= {-1}, f"row {row}: {force} answers no earlier step"
        answered.append(earlier[-1] if earlier else -1)
    assert answered == sorted(answered)  # each answer is newer than the one before
    assert max(answered) > 0
    assert not component_processes("ros2_bridge_latest")


def test_a_node_that_stops_answering_fails_the_run_naming_the_topic(tmp_path, write_config, standin):
    import pandas as pd

    port = _free_port()
    last = 40  # the node answers the steps up to this one
    standin(port, "--answer-until", str(epoch_ns(EPOCH) + last * STEP_NS))
    record = tmp_path / "rec"
    result = orchestrator("run", write_config(config("ros2_bridge_silent", port, timeout="3 s")), "--record", record)
    out = result.stdout + result.stderr
    assert result.returncode == 1, out
    t = epoch_ns(EPOCH) + (last + 1) * STEP_NS
    assert f"no message on /spring/effort stamped {t // 10**9}.{t % 10**9:09d}" in out, out
    assert f"failed in step {last + 1}" in out, out
    assert len(pd.read_parquet(record / "signals.parquet")) == last + 2  # rows 0..last+1: the answered steps'
    assert not component_processes("ros2_bridge_silent")


def test_no_router_or_no_node_fails_the_start_naming_it(tmp_path, write_config, standin):
    port = _free_port()
    result = orchestrator("run", write_config(config("ros2_bridge_alone", port, timeout="1 s")))
    out = result.stdout + result.stderr
    assert result.returncode == 1, out
    assert (
        f"failed in instantiate: ComponentError: cannot reach the ROS 2 router at tcp/127.0.0.1:{port} "
        "within 1 s" in out
    ), out
    standin(port, "--state", "/other/joint_states")  # a node, but not on the bridge's input topic
    result = orchestrator("run", write_config(config("ros2_bridge_alone", port, timeout="2 s")))
    out = result.stdout + result.stderr
    assert result.returncode == 1, out
    assert (
        "no ROS 2 node subscribes to /spring/joint_states (sensor_msgs::msg::dds_::JointState_) in domain 0 "
        f"at tcp/127.0.0.1:{port} within 2 s"
    ) in out, out
    assert not component_processes("ros2_bridge_alone")


def test_a_run_stopped_while_the_bridge_waits_ends_its_wait(tmp_path, write_config, standin):
    port = _free_port()
    node = standin(port, "--answer-until", str(epoch_ns(EPOCH) + 5 * STEP_NS))
    record = tmp_path / "rec"
    # the bridge would wait 10 min: only the interrupt can end its wait before the orchestrator kills it
    run = start_run(write_config(config("ros2_bridge_stop", port, timeout="10 min", step_timeout="20 min")), record)
    try:
        wait_until(lambda: node.waiting.exists(), "a step the node leaves unanswered", 120, run)
        run.send_signal(signal.SIGINT)
        out, err = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
    assert run.returncode == 130, out + err
    log = (record / "logs" / "node.0.log").read_text()
    assert "Interrupted: the run is ending: stopped waiting for /spring/effort" in log, log
    assert not component_processes("ros2_bridge_stop")


@pytest.mark.parametrize(
    "key, value, words",
    [
        (
            "outputs.force.type",
            "nav_msgs/msg/Odometry",
            ["topic /spring/effort: the bridge cannot map message type 'nav_msgs/msg/Odometry'", "sensor_msgs/msg/Imu"],
        ),
        ("outputs.force.topic", "/spring/effort-command", ["'/spring/effort-command' is not a ROS 2 topic name"]),
    ],
)
def test_check_refuses_what_the_bridge_cannot_map_with_exit_2(write_config, key, value, words):
    path = write_config(config("ros2_bridge_check", 7447))
    assert orchestrator("check", path).returncode == 0
    result = orchestrator("check", path, "--set", f"components.node.parameters.{key}={value}")
    assert result.returncode == 2, result.stdout + result.stderr
    assert f"components.node.parameters.{key}" in result.stderr, result.stderr
    assert all(w in result.stderr for w in words), result.stderr


def _ros2_with_rmw_zenoh() -> bool:
    import shutil

    if shutil.which("ros2") is None:
        return False
    found = subprocess.run(["ros2", "pkg", "prefix", "rmw_zenoh_cpp"], capture_output=True, timeout=60)
    with socket.socket() as s:  # rmw_zenohd's own port, which this test's router takes
        free = s.connect_ex(("127.0.0.1", 7447)) != 0
    return found.returncode == 0 and free


@pytest.mark.ros2
def test_the_guides_rclpy_node_in_the_loop_over_a_real_rmw_zenohd(tmp_path, write_config):
    """On a machine with ROS 2 and rmw_zenoh_cpp (skipped here): rmw_zenohd, the guide's rclpy node
    (docs/guides/ros2.md, run as written) and the run give the PD loop of the stand-in, bit for bit."""
    import os

    import pandas as pd

    if not _ros2_with_rmw_zenoh():
        pytest.skip("needs ros2 with rmw_zenoh_cpp, and port 7447 free for its router")
    guide = (ROOT / "docs" / "guides" / "ros2.md").read_text()
    node_source = next(block for block in guide.split("```python\n")[1:] if "class PD(Node)" in block).split("```")[0]
    (tmp_path / "pd.py").write_text(node_source)
    env = {**os.environ, "RMW_IMPLEMENTATION": "rmw_zenoh_cpp", "ROS_DOMAIN_ID": "42"}
    started = []
    try:
        started.append(
            subprocess.Popen(
                ["ros2", "run", "rmw_zenoh_cpp", "rmw_zenohd"],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
        )
        started.append(
            subprocess.Popen(
                ["python3", str(tmp_path / "pd.py"), "--ros-args", "-p", "use_sim_time:=true"],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
        )
        text = config("ros2_bridge_rclpy", 7447).replace("domain_id: 0", "domain_id: 42")
        text = text.replace("endpoint: tcp/127.0.0.1:7447", "endpoint: tcp/localhost:7447")
        # the guide's node answers on one topic
        text = "\n".join(line for line in text.splitlines() if "force_array" not in line)
        record = tmp_path / "rec"
        result = orchestrator("run", write_config(text), "--record", record)
        assert result.returncode == 0, result.stdout + result.stderr
    finally:
        for process in reversed(started):
            process.send_signal(signal.SIGINT)
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
    signals = pd.read_parquet(record / "signals.parquet")
    for column, values in reference(STEPS).items():
        assert signals[column].to_numpy().tobytes() == values.tobytes(), column


def test_check_refuses_a_second_clock_from_the_live_ros2_view(write_config, monkeypatch):
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    path = write_config(config("ros2_bridge_clock", 7447) + "ros2: {endpoint: tcp/localhost:7447}\n")
    result = orchestrator("check", path)
    assert result.returncode == 2, result.stdout + result.stderr
    assert (
        "ros2: the live ROS 2 view would publish /clock in domain 0, where the bridge 'node' publishes the run's /clock"
    ) in result.stderr, result.stderr
    assert orchestrator("check", path, "--set", "ros2.topics=[/tf]").returncode == 0
    assert orchestrator("check", path, "--set", "components.node.parameters.clock=false").returncode == 0
    assert orchestrator("check", path, "--set", "components.node.parameters.domain_id=3").returncode == 0
    plain = write_config(config("ros2_bridge_clock", 7447), "plain.yaml")
    result = orchestrator("run", plain, "--ros2")  # refused before anything starts
    assert result.returncode == 2 and "--ros2: the live ROS 2 view would publish /clock" in result.stderr, result.stderr
