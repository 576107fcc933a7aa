"""``orchestrator router --ros2`` as a user runs it on a machine without ROS: a real router process;
a real ``orchestrator run ... --ros2 tcp/127.0.0.1:PORT`` through it (the live view is a Zenoh
client of the router, so what it publishes reaches others only through the router); a Zenoh peer
linked to the router, as rmw_zenoh's nodes are, subscribed to rmw_zenoh's keys, sees the run's
node token and its /clock. A second router on the same port exits 2 naming it; SIGTERM and SIGINT
end the router with 0 and free its port; a ros2.bridge linked to the router with no ROS node on it
fails naming the cause. Every process started here is stopped here.
"""

from __future__ import annotations

import errno
import os
import re
import signal
import socket
import subprocess
import sys
import threading

import pytest

from components.ros2.router import hint
from tests.conftest import ROOT, component_processes, orchestrator
from tests.integration.test_ros2_bridge import config as bridge_config
from tests.integration.test_rosbag_export import _parquet, _stamps

pytestmark = pytest.mark.integration

DOMAIN = 11
CONFIG = ROOT / "configs" / "capture_tumbling_target.yaml"
CLOCK_KEY = re.compile(rf"{DOMAIN}/clock/rosgraph_msgs::msg::dds_::Clock_/RIHS01_[0-9a-f]{{64}}")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _nothing_listens(port: int) -> bool:
    """Refused: the router's listener is closed (its links' sockets may be in TIME_WAIT, so a plain
    bind could still fail)."""
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == errno.ECONNREFUSED


class Router:
    """``orchestrator router --ros2 --listen tcp/127.0.0.1:PORT``, up once it has said where it listens."""

    def __init__(self, port: int):
        self.endpoint = f"tcp/127.0.0.1:{port}"
        self.port = port
        self.process = subprocess.Popen(
            [sys.executable, "-m", "orchestrator.cli", "router", "--ros2", "--listen", self.endpoint],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.said = [self.process.stdout.readline() for _ in range(4)]  # '' if it ended
        assert self.said[0].startswith(f"ROS 2 router (rmw_zenohd's configuration) listening on {self.endpoint}"), (
            "".join(self.said) + self.process.stderr.read() if self.process.poll() is not None else self.said
        )

    def stop(self, sig=signal.SIGTERM) -> tuple[int, str]:
        """Send ``sig``; (exit code, stderr). Killed if it does not end."""
        if self.process.poll() is None:
            self.process.send_signal(sig)
        try:
            _, err = self.process.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            _, err = self.process.communicate()
        return self.process.returncode, err


@pytest.fixture
def routers():
    started: list[Router] = []

    def start(port: int) -> Router:
        started.append(Router(port))
        return started[-1]

    yield start
    for r in started:
        r.stop(signal.SIGKILL)


class RosNode:
    """A peer of the router, as an rmw_zenoh node is: its graph cache's liveliness subscriber and a
    subscription to /clock's data key (any type hash)."""

    def __init__(self, endpoint: str):
        import zenoh

        from components import bus

        self.session = zenoh.open(bus.session_config(connect=[endpoint], mesh=True))
        self.tokens: list[str] = []
        self.clock: list[tuple[str, bytes, bytes | None]] = []
        self.arrived = threading.Condition()
        self.graph = self.session.liveliness().declare_subscriber(f"@ros2_lv/{DOMAIN}/**", self._token, history=True)
        self.data = self.session.declare_subscriber(f"{DOMAIN}/clock/**", self._sample)

    def _token(self, sample) -> None:
        self.tokens.append(str(sample.key_expr))

    def _sample(self, sample) -> None:
        with self.arrived:
            self.clock.append(
                (
                    str(sample.key_expr),
                    sample.payload.to_bytes(),
                    sample.attachment.to_bytes() if sample.attachment is not None else None,
                )
            )
            self.arrived.notify_all()

    def wait_for(self, predicate, timeout_s: float) -> None:
        with self.arrived:
            self.arrived.wait_for(predicate, timeout_s)

    def close(self) -> None:
        for declared in (self.data, self.graph):
            declared.undeclare()
        self.session.close()


def test_a_run_publishes_through_the_router_and_sigterm_ends_it(routers, tmp_path):
    from rosbags.typesys import Stores, get_typestore

    router = routers(_free_port())
    assert f"orchestrator run CONFIG --ros2 {router.endpoint}" in router.said[1]
    record = tmp_path / "rec"
    node = RosNode(router.endpoint)
    try:
        result = orchestrator(
            "run",
            CONFIG,
            "--set",
            "run.duration=0.5 s",
            "--set",
            "ros2.rate=100 Hz",
            "--record",
            record,
            "--ros2",
            router.endpoint,
            env={**os.environ, "ROS_DOMAIN_ID": str(DOMAIN)},
        )
        assert result.returncode == 0, result.stderr
        assert "cannot reach the ROS 2 router" not in result.stderr, result.stderr
        stamps = [int(s) for s in _stamps(record, _parquet(record))]
        # the last /clock may still be on its way through the router when the run returns
        node.wait_for(lambda: len(node.clock) >= len(stamps), timeout_s=20)
    finally:
        node.close()
    assert any("/NN/%/%/zenorbit_capture_tumbling_target" in t for t in node.tokens), node.tokens
    typestore = get_typestore(Stores.ROS2_JAZZY)
    received = []
    for key, payload, attachment in node.clock:
        assert CLOCK_KEY.fullmatch(key), key
        assert attachment is not None and len(attachment) == 33  # rmw_zenoh's attachment
        clock = typestore.deserialize_cdr(payload, "rosgraph_msgs/msg/Clock").clock
        received.append(clock.sec * 1_000_000_000 + clock.nanosec)
    assert received, "no /clock came through the router"
    assert received == sorted(set(received)) and set(received) <= set(stamps), (received, stamps)
    print(f"/clock: {len(received)} of the run's {len(stamps)} rows came through the router")

    code, err = router.stop(signal.SIGTERM)
    assert code == 0, err
    assert "ROS 2 router stopped" in err
    assert _nothing_listens(router.port)
    assert not component_processes("capture_tumbling_target")


def test_a_taken_port_exits_2_and_sigint_ends_the_router_with_0(routers):
    first = routers(_free_port())
    second = subprocess.run(
        [sys.executable, "-m", "orchestrator.cli", "router", "--ros2", "--listen", first.endpoint],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert second.returncode == 2, second.stderr
    assert second.stderr.startswith(f"error: cannot listen on {first.endpoint}: Address already in use"), second.stderr
    assert "orchestrator router --ros2" in second.stderr and not second.stdout
    assert first.process.poll() is None  # the first one goes on
    code, err = first.stop(signal.SIGINT)
    assert code == 0, err
    assert _nothing_listens(first.port)


def test_a_bridge_on_the_router_with_no_node_names_the_cause(routers, write_config):
    router = routers(_free_port())
    result = orchestrator("run", write_config(bridge_config("ros2_router_alone", router.port, timeout="1 s")))
    out = result.stdout + result.stderr
    assert result.returncode == 1, out
    assert (
        f"no ROS 2 node publishes /spring/effort (trajectory_msgs::msg::dds_::JointTrajectory_) in domain 0 at "
        f"{router.endpoint} within 1 s: start the node before the run (or raise timeout); "
        f"{hint('transport: rclpy')}"
    ) in out, out
    code, err = router.stop()
    assert code == 0, err
    assert not component_processes("ros2_router_alone")


def test_no_router_names_the_cause(write_config, tmp_path):
    endpoint = f"tcp/127.0.0.1:{_free_port()}"  # nothing listens there
    view = orchestrator("run", CONFIG, "--set", "run.duration=0.1 s", "--ros2", endpoint)
    assert view.returncode == 0, view.stderr
    assert f"cannot reach the ROS 2 router at {endpoint}" in view.stderr and hint() in view.stderr, view.stderr
    bridge = orchestrator(
        "run", write_config(bridge_config("ros2_no_router", int(endpoint.rsplit(":", 1)[1]), timeout="1 s"))
    )
    assert bridge.returncode == 1, bridge.stderr
    assert (
        f"cannot reach the ROS 2 router at {endpoint} within 1 s (endpoint sets where): {hint('transport: rclpy')}"
    ) in bridge.stdout + bridge.stderr
    assert not component_processes("ros2_no_router")
