"""The ``rclpy`` transport: the ROS 2 side as a real rclpy node, in a process of its own
(:mod:`components.ros2.rclpy_side`), on whatever middleware the user's ROS 2 environment selects
(``RMW_IMPLEMENTATION``; Jazzy's default is Fast DDS), so a stock ROS 2 sees the run.

rclpy lives in another process because the Python that has it may not be this one (a sourced
/opt/ros for the system's Python, a venv with the Jazzy wheels, which re-execute their interpreter
with their own ``LD_LIBRARY_PATH``), and so that nothing of ROS shares a process with the run's bus.
:class:`RclpyNode` has the interface of :class:`components.ros2.rmw_zenoh.Node` (publishers that
``put`` CDR bytes, subscriptions calling a handler), so the observer and ``ros2.bridge`` use either.

Which Python: the one given (``ros2.python``, a bridge's ``python``), else ``ZENORBIT_ROS2_PYTHON``,
else this Python, else ``python3`` on the PATH: the first that imports rclpy.
"""

from __future__ import annotations

import functools
import json
import os
import shutil
import struct
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path

from components.errors import ComponentError

PYTHON_ENV = "ZENORBIT_ROS2_PYTHON"
SIDE = Path(__file__).with_name("rclpy_side.py")
HEADER = struct.Struct("<IB")
ENTITY_ID = struct.Struct("<I")
START_TIMEOUT_S = 60.0  # importing rclpy and joining the DDS domain; a first import compiles .pyc files
PROBE_TIMEOUT_S = 60.0
STREAM_DEPTH = 100  # KEEP_LAST depth of a volatile subscription: a burst of answers waits whole
LATCHED_DEPTH = 1  # as tf2's static broadcaster and robot_state_publisher
ZENOH, RCLPY, AUTO = "zenoh", "rclpy", "auto"
TRANSPORTS = (ZENOH, RCLPY, AUTO)


@functools.cache
def _imports_rclpy(python: str) -> str | None:
    """None if ``python`` imports rclpy, else why not (one line)."""
    try:
        done = subprocess.run(
            [python, "-c", "import rclpy"],
            capture_output=True,
            text=True,
            timeout=PROBE_TIMEOUT_S,
            stdin=subprocess.DEVNULL,
        )
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"{python}: {type(e).__name__}: {e}"
    if done.returncode == 0:
        return None
    last = (done.stderr.strip().splitlines() or [f"exit code {done.returncode}"])[-1]
    return f"{python}: {last}"


def find_python(configured: str | None = None) -> tuple[str | None, list[str]]:
    """The Python to run rclpy with, and why each one tried could not (empty when one could)."""
    if configured:
        candidates = [configured]
    else:
        candidates = [p for p in (os.environ.get(PYTHON_ENV), sys.executable, shutil.which("python3")) if p]
    tried = []
    for python in dict.fromkeys(candidates):
        problem = _imports_rclpy(python)
        if problem is None:
            return python, []
        tried.append(problem)
    return None, tried


def choose(transport: str, configured_python: str | None = None) -> tuple[str, str | None, str]:
    """(``zenoh`` or ``rclpy``, the Python for rclpy, a one-line reason) for ``transport``
    (zenoh | rclpy | auto); raises ComponentError when ``rclpy`` was asked for and no Python has it."""
    if transport == ZENOH:
        return ZENOH, None, "transport: zenoh (rmw_zenoh's wire, through its router)"
    python, tried = find_python(configured_python)
    if python is not None:
        return RCLPY, python, f"transport: rclpy ({python} imports rclpy)"
    if transport == RCLPY:
        raise ComponentError(
            "transport rclpy: no Python here imports rclpy (" + "; ".join(tried) + "): source your "
            f"ROS 2 (source /opt/ros/jazzy/setup.bash), or give the Python that has it (ros2.python, "
            f"or {PYTHON_ENV}), or use transport: zenoh with rmw_zenoh's router (rmw_zenohd, "
            f"or orchestrator router --ros2 without ROS)"
        )
    return ZENOH, None, "transport: auto chose zenoh (no Python here imports rclpy: " + "; ".join(tried) + ")"


class _Entity:
    def __init__(self, node: RclpyNode, entity_id: int, topic: str, msgtype: str, role: str):
        self.node, self.id, self.topic, self.msgtype, self.role = node, entity_id, topic, msgtype, role
        self.sequence = 0


class RclpyPublisher(_Entity):
    def put(self, cdr: bytes, source_timestamp_ns: int | None = None) -> None:
        """Send one message (CDR with its encapsulation header); rclpy stamps its own source time."""
        self.sequence += 1
        self.node._send(b"M", ENTITY_ID.pack(self.id) + bytes(cdr))


class RclpySubscription(_Entity):
    pass


class RclpyNode:
    """A ROS 2 node in an rclpy process of its own. ``warn(text)`` hears what that process could
    not do (a message package missing there); its stderr is this process's. ``discover_s``: how
    long, at most, the node gives the middleware's discovery before it reports ready (see
    rclpy_side.py), so that subscribers already running get the first messages."""

    def __init__(
        self,
        python: str,
        domain_id: int,
        name: str,
        namespace: str = "/",
        warn: Callable[[str], None] | None = None,
        start_timeout_s: float = START_TIMEOUT_S,
        discover_s: float = 0.0,
    ):
        self.python, self.domain_id, self.name, self.namespace = python, int(domain_id), name, namespace
        self.warn = warn or (lambda text: print(f"ros2: {text}", file=sys.stderr, flush=True))
        self.entities: list[_Entity] = []
        self.failed: dict[int, str] = {}  # entity id -> why it could not be made
        self._handlers: dict[int, Callable] = {}
        self._lock = threading.Condition()
        self._replies: dict[int, dict] = {}
        self._requests = 0
        self._send_lock = threading.Lock()
        self.ready: dict | None = None
        self.process = subprocess.Popen(
            [
                python,
                str(SIDE),
                "--domain",
                str(self.domain_id),
                "--node",
                name,
                "--namespace",
                namespace,
                "--discover",
                f"{discover_s:g}",
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=None,
        )
        # both piped: typed once here for the per-message writes and the reader
        assert self.process.stdin is not None and self.process.stdout is not None
        self._stdin, self._stdout = self.process.stdin, self.process.stdout
        self._reader = threading.Thread(target=self._read, name="rclpy-reader", daemon=True)
        self._reader.start()
        with self._lock:
            if not self._lock.wait_for(
                lambda: self.ready is not None or self.process.poll() is not None, start_timeout_s
            ):
                self.close()
                raise ComponentError(f"the rclpy node ({python}) did not come up within {start_timeout_s:g} s")
        if self.ready is None:
            code = self.process.wait()
            raise ComponentError(
                f"the rclpy node ({python}) exited with code {code} before it came up (its message is above)"
            )

    @property
    def rmw(self) -> str:
        ready = self.ready
        assert ready is not None  # __init__ waited for it
        return ready["rmw"]

    @property
    def alive(self) -> bool:
        return self.process.poll() is None

    def publisher(
        self, topic: str, msgtype: str, typestore=None, latched: bool = False, block: bool = False
    ) -> RclpyPublisher:
        """A publisher of ``msgtype`` on ``topic``: reliable, TRANSIENT_LOCAL depth 1 if ``latched``,
        else volatile KEEP_ALL (a sample stays until every matched reader has it: a reader that lost
        one gets it again, however far the writer has gone on; KEEP_LAST would let it go).
        (``typestore`` and ``block``: for the interface of rmw_zenoh.Node; a pipe blocks.)"""
        return self._declare(b"P", RclpyPublisher, topic, msgtype, latched)

    def subscriber(
        self, topic: str, msgtype: str, typestore, handler: Callable[[bytes, object], None], latched: bool = False
    ) -> RclpySubscription:
        """A subscription to ``topic``; ``handler(cdr, None)`` on this node's reader thread."""
        subscription = self._declare(b"S", RclpySubscription, topic, msgtype, latched)
        self._handlers[subscription.id] = handler
        return subscription

    def _declare(self, kind: bytes, cls, topic: str, msgtype: str, latched: bool):
        entity = cls(self, len(self.entities), topic, msgtype, "publisher" if kind == b"P" else "subscription")
        self.entities.append(entity)
        depth = LATCHED_DEPTH if latched else (None if kind == b"P" else STREAM_DEPTH)  # None: KEEP_ALL
        self._send(
            kind,
            json.dumps({"id": entity.id, "topic": topic, "type": msgtype, "latched": latched, "depth": depth}).encode(),
        )
        return entity

    def unmatched(self, timeout_s: float, exclude: tuple[str, ...] = ()) -> list[tuple[str, str, str]]:
        """(role, topic, type) of each publisher no subscription is matched with and each subscription
        no publisher is matched with (DDS matching: data would flow), but the ``exclude`` topics."""
        reply = self._ask({"topics": []}, timeout_s)
        return [
            (e.role, e.topic, e.msgtype)
            for e in self.entities
            if e.topic not in exclude and e.id not in self.failed and not reply["matched"].get(str(e.id))
        ]

    def graph(self, topics: list[str], timeout_s: float) -> list[tuple[str, str, str, str]]:
        """(role, topic, type, node) of every other node's publisher and subscription on ``topics``."""
        return [tuple(entry) for entry in self._ask({"topics": list(topics)}, timeout_s)["graph"]]

    def _ask(self, request: dict, timeout_s: float) -> dict:
        with self._lock:
            self._requests += 1
            number = self._requests
        self._send(b"G", json.dumps({**request, "request": number}).encode())
        with self._lock:
            if not self._lock.wait_for(lambda: number in self._replies or not self.alive, timeout_s):
                raise ComponentError(f"the rclpy node did not answer within {timeout_s:g} s")
            if number not in self._replies:
                raise ComponentError(f"the rclpy node exited with code {self.process.poll()}")
            return self._replies.pop(number)

    def _send(self, kind: bytes, payload: bytes) -> None:
        frame = HEADER.pack(len(payload), kind[0]) + payload
        try:
            with self._send_lock:
                self._stdin.write(frame)
                self._stdin.flush()
        except (BrokenPipeError, ValueError, OSError):
            raise ComponentError(
                f"the rclpy node ({self.python}) has exited (code {self.process.poll()}; its message is above)"
            ) from None

    def _read(self) -> None:
        stream = self._stdout
        while True:
            header = stream.read(HEADER.size)
            if len(header) < HEADER.size:
                break
            size, kind = HEADER.unpack(header)
            payload = stream.read(size)
            if len(payload) < size:
                break
            if kind == ord("M"):
                (entity,) = ENTITY_ID.unpack_from(payload)
                handler = self._handlers.get(entity)
                if handler is not None:
                    handler(payload[ENTITY_ID.size :], None)
            elif kind == ord("W"):
                message = json.loads(payload)
                if message.get("id") is not None:
                    self.failed[message["id"]] = message["text"]
                self.warn(message["text"])
            elif kind in (ord("R"), ord("G")):
                message = json.loads(payload)
                with self._lock:
                    if kind == ord("R"):
                        self.ready = message
                    else:
                        self._replies[message["request"]] = message
                    self._lock.notify_all()
        with self._lock:
            self._lock.notify_all()

    def close(self, timeout_s: float = 10.0) -> None:
        """Finish: the node publishes what it was given, waits (bounded) for its subscribers to
        acknowledge it, and exits; killed if it does not within ``timeout_s``."""
        if self.process.poll() is None:
            try:
                self._send(b"Q", b"")
                self._stdin.close()
            except (ComponentError, OSError):
                pass
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self._reader.join(timeout=1.0)
