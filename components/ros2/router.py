"""A ROS 2 router without ROS: ``orchestrator router --ros2 [--listen EP]``.

rmw_zenoh's nodes (``RMW_IMPLEMENTATION=rmw_zenoh_cpp``), the live view (``orchestrator run CFG
--ros2 [ENDPOINT]``, transport zenoh) and ``ros2.bridge`` (``transport: zenoh``) meet at a Zenoh
router; on a ROS machine that is ``ros2 run rmw_zenoh_cpp rmw_zenohd``. This module is that router
for a machine without ROS: a plain Zenoh session in router mode, in the foreground, with the values
of rmw_zenohd's default configuration (``SETTINGS``) and its listen endpoint (``DEFAULT_LISTEN``),
on Zenoh's own runtime (a router forwards every link's traffic: not the one-thread ``bus.RUNTIME``
of a component's session). It stops on SIGTERM or SIGINT (exit 0); an endpoint that is malformed or
already taken: :class:`RouterError` (exit 2), naming it.

It speaks no ROS of its own: it routes samples, liveliness tokens and queries between whoever is
linked to it, whatever the ROS domain (the domain is the first part of each key).

``hint(option)`` is the text the live view and ``ros2.bridge`` add where no router, or no ROS node,
answers.
"""

from __future__ import annotations

import json
import os
import re
import signal
import sys
import threading
from collections.abc import Callable

DEFAULT_LISTEN = "tcp/[::]:7447"  # rmw_zenohd's listen/endpoints: every interface, IPv4 and IPv6
DEFAULT_PORT = 7447

# ros2/rmw_zenoh rmw_zenoh_cpp/config/DEFAULT_RMW_ZENOH_ROUTER_CONFIG.json5 (rolling, read at commit
# 076f2e7): the values its "ROS setting" comments choose, and those a router's behaviour rests on;
# every key not here keeps Zenoh's default, which that file repeats. Values as JSON.
SETTINGS: dict[str, object] = {
    "mode": "router",
    "listen/timeout_ms": 0,  # no retry: a taken port fails at once ...
    "listen/exit_on_failure": True,  # ... and the router does not start
    "connect/endpoints": [],
    "scouting/multicast/enabled": False,  # "ROS setting: disable multicast discovery by default"
    "scouting/gossip/enabled": True,
    "scouting/gossip/multihop": False,
    "scouting/gossip/target": {"router": ["router", "peer"], "peer": ["router"]},  # peers learn each other here
    "timestamping/enabled": {"router": True, "peer": True, "client": True},  # transient local needs them
    "queries_default_timeout": 600000,  # ms: slow service servers at launch
    "routing/router/peers_failover_brokering": False,  # each rmw_zenoh peer connects to every other
    "transport/unicast/open_timeout": 60000,  # ms: many nodes starting at once
    "transport/unicast/accept_timeout": 60000,
    "transport/unicast/accept_pending": 10000,
    "transport/unicast/max_sessions": 10000,
    "transport/unicast/max_links": 1,
    "transport/link/tx/lease": 60000,  # ms
    "transport/link/tx/keep_alive": 2,  # per lease: nodes on the loopback
    "transport/shared_memory/enabled": False,  # "ROS setting: disabled by default until fully tested"
    "adminspace/enabled": True,
    "adminspace/permissions/read": True,
    "adminspace/permissions/write": False,
}

PROTOCOLS = ("tcp", "udp")  # rmw_zenoh's nodes link over tcp; tls and quic would need certificates here
_ENDPOINT = re.compile(r"(?P<protocol>[A-Za-z0-9\-]+)/(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9.\-]+):(?P<port>\d+)")
_ANY_HOST = ("[::]", "0.0.0.0")


class RouterError(Exception):
    """The router cannot start (exit 2): the message says what was expected beside what was given."""


def hint(rclpy_option: str = "--ros2 rclpy") -> str:
    """What to check when no router, or no ROS node, answers: the ROS side may be on DDS, or
    rmw_zenoh without its router. ``rclpy_option``: how the caller's user picks rclpy."""
    return (
        f"nothing on this ROS domain answers; is your ROS on Fast DDS? use `{rclpy_option}`, or rmw_zenoh "
        f"with its router (`orchestrator router --ros2` or `ros2 run rmw_zenoh_cpp rmw_zenohd`)"
    )


def check_endpoint(endpoint: str) -> str | None:
    """Why ``endpoint`` cannot be a listen endpoint of the router, or None."""
    example = (
        f"e.g. {DEFAULT_LISTEN} (rmw_zenohd's: every interface) or tcp/127.0.0.1:{DEFAULT_PORT} (this machine only)"
    )
    match = _ENDPOINT.fullmatch(endpoint)
    if match is None:
        return f"expected PROTOCOL/HOST:PORT, {example}; got {endpoint!r}"
    if match["protocol"] not in PROTOCOLS:
        return (
            f"expected the protocol {' or '.join(PROTOCOLS)} (rmw_zenoh's nodes use tcp), {example}; got {endpoint!r}"
        )
    port = int(match["port"])
    if not 1 <= port <= 65535:
        return f"expected a port from 1 to 65535 (ROS nodes must be told it: not 0), {example}; got {endpoint!r}"
    return None


def run_endpoint(listen: str) -> str:
    """The endpoint a run on this machine gives ``--ros2`` to reach a router listening on ``listen``."""
    match = _ENDPOINT.fullmatch(listen)
    if match is None or match["host"] not in _ANY_HOST:
        return listen
    return f"{match['protocol']}/localhost:{match['port']}"


def config(listen: list[str]):
    """The router's Zenoh config: ``SETTINGS``, listening on ``listen``."""
    import zenoh

    problems = [f"{endpoint}: {problem}" for endpoint in listen if (problem := check_endpoint(endpoint))]
    if problems:
        raise RouterError("; ".join(problems))
    conf = zenoh.Config()
    for key, value in SETTINGS.items():
        conf.insert_json5(key, json.dumps(value))
    conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    return conf


def _reason(error: Exception) -> str:
    """Zenoh's error without its source locations: the OS's words when it has them."""
    text = str(error)
    os_error = re.search(r"([A-Za-z][^:\[\]]*\(os error \d+\))", text)
    if os_error:
        return os_error.group(1).strip()
    return re.sub(r" at \S+\.rs:\d+\.?", "", text).strip()


def serve(
    listen: list[str] | None = None, out: Callable[[str], None] | None = None, stop: threading.Event | None = None
) -> int:
    """Route until SIGTERM or SIGINT (or ``stop`` is set); 0. RouterError when it cannot listen."""
    import zenoh

    from components import bus

    listen = list(listen or [DEFAULT_LISTEN])
    out = out or (lambda line: print(line, flush=True))
    conf = config(listen)
    # Zenoh's own runtime: a bus.RUNTIME in the environment is inherited from a process of ours that
    # opened a session (bus.session_config sets it), not the user's choice
    if os.environ.get("ZENOH_RUNTIME", bus.RUNTIME) == bus.RUNTIME:
        os.environ["ZENOH_RUNTIME"] = "()"
    done = stop or threading.Event()
    previous = {}
    if threading.current_thread() is threading.main_thread():
        previous = {sig: signal.signal(sig, lambda *_: done.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        try:
            session = zenoh.open(conf)
        except zenoh.ZError as e:
            reason = _reason(e)
            taken = "in use" in reason
            raise RouterError(
                f"cannot listen on {', '.join(listen)}: {reason}"
                + (
                    " (is a router there already, rmw_zenohd or another `orchestrator router --ros2`? use it, or "
                    "give a free port: --listen tcp/[::]:PORT)"
                    if taken
                    else ""
                )
            ) from None
        try:
            reach = run_endpoint(listen[0])
            everywhere = any((m := _ENDPOINT.fullmatch(e)) is not None and m["host"] in _ANY_HOST for e in listen)
            override = (
                ""
                if reach == f"tcp/localhost:{DEFAULT_PORT}"
                # rmw_zenoh's nodes look there
                else f" ZENOH_CONFIG_OVERRIDE='connect/endpoints=[\"{reach}\"]'"
            )
            out(
                f"ROS 2 router (rmw_zenohd's configuration) listening on {', '.join(listen)}"
                f"{' (every interface of this machine)' if everywhere else ''}; SIGTERM or Ctrl-C stops it"
            )
            out(f"  a run:          orchestrator run CONFIG --ros2 {reach}")
            out(f"  a ros2.bridge:  transport: zenoh, endpoint: {reach}")
            out(f"  ROS 2 nodes:    RMW_IMPLEMENTATION=rmw_zenoh_cpp{override}, the run's ROS_DOMAIN_ID")
            while not done.wait(0.2):
                pass
        finally:
            session.close()
        print("ROS 2 router stopped", file=sys.stderr, flush=True)
        return 0
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
