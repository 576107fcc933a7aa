"""``orchestrator router --ros2`` (components/ros2/router.py): rmw_zenohd's configuration values in
the Zenoh config it opens, the endpoints it accepts and refuses, and its exit codes; the hint the
live view and ros2.bridge give where nothing answers."""

from __future__ import annotations

import json
import socket
import threading

import pytest

from components.ros2 import router
from orchestrator import cli

# DEFAULT_RMW_ZENOH_ROUTER_CONFIG.json5 (ros2/rmw_zenoh, rolling), as its file writes them
RMW_ZENOHD = {
    "mode": "router",
    "scouting/multicast/enabled": False,
    "scouting/gossip/enabled": True,
    "scouting/gossip/multihop": False,
    "scouting/gossip/target": {"router": ["router", "peer"], "peer": ["router"]},
    "timestamping/enabled": {"router": True, "peer": True, "client": True},
    "queries_default_timeout": 600000,
    "routing/router/peers_failover_brokering": False,
    "transport/unicast/open_timeout": 60000,
    "transport/unicast/accept_timeout": 60000,
    "transport/unicast/accept_pending": 10000,
    "transport/unicast/max_sessions": 10000,
    "transport/link/tx/lease": 60000,
    "transport/link/tx/keep_alive": 2,
    "transport/shared_memory/enabled": False,
    "listen/timeout_ms": 0,
    "listen/exit_on_failure": True,
}


def test_the_config_has_rmw_zenohds_values():
    config = router.config(["tcp/127.0.0.1:7447"])
    for key, value in RMW_ZENOHD.items():
        assert json.loads(config.get_json(key)) == value, key
    assert json.loads(config.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7447"]
    assert router.DEFAULT_LISTEN == "tcp/[::]:7447"


@pytest.mark.parametrize(
    "endpoint",
    [
        "tcp/[::]:7447",
        "tcp/0.0.0.0:7447",
        "tcp/127.0.0.1:1",
        "tcp/localhost:65535",
        "udp/10.0.0.2:7447",
        "tcp/[::1]:7447",
        "tcp/ros-host.local:7447",
    ],
)
def test_endpoints_accepted(endpoint):
    assert router.check_endpoint(endpoint) is None


@pytest.mark.parametrize(
    "endpoint, expected",
    [
        ("localhost:7447", "expected PROTOCOL/HOST:PORT"),
        ("tcp/localhost", "expected PROTOCOL/HOST:PORT"),
        ("tcp/local host:7447", "expected PROTOCOL/HOST:PORT"),
        ("tls/localhost:7447", "expected the protocol tcp or udp"),
        ("quic/[::]:7447", "expected the protocol tcp or udp"),
        ("tcp/localhost:0", "expected a port from 1 to 65535"),
        ("tcp/localhost:65536", "expected a port from 1 to 65535"),
    ],
)
def test_endpoints_refused_name_what_was_expected_and_given(endpoint, expected):
    problem = router.check_endpoint(endpoint)
    assert problem is not None and problem.startswith(expected) and problem.endswith(f"got {endpoint!r}")
    with pytest.raises(router.RouterError, match="expected"):
        router.config([endpoint])


@pytest.mark.parametrize(
    "listen, run",
    [
        ("tcp/[::]:7447", "tcp/localhost:7447"),
        ("tcp/0.0.0.0:8000", "tcp/localhost:8000"),
        ("tcp/127.0.0.1:7447", "tcp/127.0.0.1:7447"),
        ("tcp/[::1]:9", "tcp/[::1]:9"),
    ],
)
def test_a_run_is_pointed_at_a_reachable_address(listen, run):
    assert router.run_endpoint(listen) == run


def test_the_hint_names_the_cause_and_both_ways_out():
    text = router.hint()
    assert text.startswith("nothing on this ROS domain answers; is your ROS on Fast DDS? use `--ros2 rclpy`")
    assert "`orchestrator router --ros2`" in text and "`ros2 run rmw_zenoh_cpp rmw_zenohd`" in text
    assert "use `transport: rclpy`" in router.hint("transport: rclpy")


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["router", "--ros2", "--listen", "localhost:7447"], "error: --listen: expected PROTOCOL/HOST:PORT"),
        (["router", "--ros2", "--listen", "tcp/[::]:7447", "--listen", "tcp/x:0"], "got 'tcp/x:0'"),
        (["router", "--ros2", "--join", "run/join/router.join"], "expected no --join"),
        (["router"], "expected --listen ENDPOINT and --join FILE (a run's router), or --ros2"),
        (["router", "--listen", "tcp/0.0.0.0:7447"], "expected --join FILE (a run's router), or --ros2"),
    ],
)
def test_usage_errors_exit_2(argv, expected, capsys):
    assert cli.main(argv) == 2
    assert expected in capsys.readouterr().err


@pytest.fixture
def zenoh_runtime(monkeypatch):
    monkeypatch.delenv("ZENOH_RUNTIME", raising=False)  # serve() sets it; put back afterwards


def test_serve_says_where_it_listens_and_how_to_reach_it(zenoh_runtime):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    lines, stop = [], threading.Event()

    def said(line):
        lines.append(line)
        stop.set()  # it listens: done

    assert router.serve([f"tcp/127.0.0.1:{port}"], out=said, stop=stop) == 0
    assert lines[0].startswith(f"ROS 2 router (rmw_zenohd's configuration) listening on tcp/127.0.0.1:{port};")
    assert f"orchestrator run CONFIG --ros2 tcp/127.0.0.1:{port}" in lines[1]
    assert f"""ZENOH_CONFIG_OVERRIDE='connect/endpoints=["tcp/127.0.0.1:{port}"]'""" in lines[3]
    with socket.socket() as s:  # closed: the port is free again
        s.bind(("127.0.0.1", port))


def test_a_taken_port_is_named_with_what_to_do(zenoh_runtime):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        endpoint = f"tcp/127.0.0.1:{taken.getsockname()[1]}"
        with pytest.raises(router.RouterError) as raised:
            router.serve([endpoint], out=lambda line: pytest.fail(f"said {line!r}"), stop=threading.Event())
    message = str(raised.value)
    assert message.startswith(f"cannot listen on {endpoint}: Address already in use (os error ")
    assert "--listen tcp/[::]:PORT" in message and ".rs:" not in message
