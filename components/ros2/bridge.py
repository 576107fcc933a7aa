"""``ros2.bridge``: a ROS 2 node in the loop. Its inputs go out to ROS 2 topics each step, stamped
with the step's time, with ``/clock``; its outputs come back from ROS 2 topics, taken by the rule of
``wait_for`` (:mod:`components.ros2.lockstep`). The ROS side (``transport``) is a real rclpy node
in a process of its own, on the middleware the user's ROS 2 selects
(:mod:`components.ros2.rclpy_transport`), or a Zenoh session of its own linked to the ROS router
(rmw_zenohd), following rmw_zenoh's conventions (:mod:`components.ros2.rmw_zenoh`); the run's own
bus is untouched either way. The mapping of variables to message fields:
:mod:`components.ros2.messages`.

Step k (``do_step(t_k, ...)``): ``/clock`` <- t_k, each input topic <- the inputs held at t_k,
stamped t_k; then each output topic's message for t_k (``stamped``) or its newest (``latest``)
gives the outputs at t_{k+1}, as a controller's outputs are. ROS time = ``run.epoch`` + t (ns since 1970,
as components/rosbag.py stamps a recording). The state of the ROS node lives outside the run: no
get_state (a restart or a swap with state is refused, naming why).
"""

from __future__ import annotations

import sys
import time
from typing import TYPE_CHECKING, cast

import numpy as np

from components.constants import NS_PER_S
from components.errors import ComponentError, ConfigError
from components.ros2 import lockstep, messages
from components.ros2.bindings import CLOCK_TOPIC, Binding, bindings
from components.ros2.rclpy_transport import AUTO, RCLPY, TRANSPORTS, RclpyNode, choose
from components.ros2.rmw_zenoh import ADMIN_SPACE, PUBLISHER, SUBSCRIPTION, dds_type_name
from components.ros2.router import hint
from components.rosbag import epoch_ns
from components.schema import Bool, Duration, Float, Int, ListOf, MapOf, OneOf, Record, Str, Vector
from components.sdk import Component, Parameter, Variable

if TYPE_CHECKING:
    import zenoh

    from components.ros2.rmw_zenoh import Node

DEFAULT_ENDPOINT = "tcp/localhost:7447"  # rmw_zenohd's own default
DEFAULT_DOMAIN_ID = 0  # ROS_DOMAIN_ID's own default
ENDPOINT = r"(tcp|udp|tls|quic)/(\[[0-9a-fA-F:]+\]|[A-Za-z0-9.\-]+):\d{1,5}"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"

_TOPIC = (
    Parameter("topic", Str(hint="a ROS 2 topic name such as /effort_command"), description="the ROS 2 topic"),
    Parameter(
        "type",
        Str(hint="a ROS 2 message type such as std_msgs/msg/Float64MultiArray"),
        description="its message type, one of the supported ones (docs/guides/ros2.md)",
    ),
    Parameter(
        "field",
        Str(hint="a field of the message type"),
        default=None,
        description="the message's field the variable is (may be left out when the type has one)",
    ),
    Parameter(
        "size",
        Int(minimum=1),
        default=None,
        description="the variable's length, for a field that is a sequence (joint values, data)",
    ),
    Parameter(
        "unit",
        Str(hint="a unit such as N*m"),
        default=None,
        description="the variable's unit (a field with a unit of its own has it by default)",
    ),
    Parameter(
        "names",
        ListOf(Str(hint="a joint name"), min_items=1, unique=True),
        default=None,
        description="joint names (JointState, JointTrajectory): published with the values, or the "
        "joints whose values are read, by name, in this order",
    ),
)
OUTPUT = Record(
    "RosOutput",
    _TOPIC
    + (
        Parameter(
            "start",
            OneOf((Float(), Vector())),
            default=None,
            description="the output at t0, before any answer (default: zeros; identity for a quaternion)",
        ),
    ),
    description="an output of the bridge: the field of the messages on a ROS 2 topic",
)
INPUT = Record(
    "RosInput",
    _TOPIC
    + (
        Parameter(
            "frame_id", Str(hint="a tf frame"), default="", description="the header's frame_id (types with a header)"
        ),
    ),
    description="an input of the bridge: published each step as the field of a ROS 2 message",
)
VARIABLE_NAME = r"[A-Za-z_][A-Za-z0-9_]*"


class Ros2Bridge(Component):
    """A ROS 2 node in the loop: inputs published to ROS 2 topics, outputs taken from ROS 2 topics,
    in lockstep with the run (``wait_for: stamped``) or not (``latest``); ``/clock`` follows the run."""

    type_name = "ros2.bridge"
    parameters = (
        Parameter(
            "wait_for",
            Str((lockstep.STAMPED, lockstep.LATEST)),
            description="stamped: step k waits for the messages stamped t_k (deterministic if the node "
            "is); latest: takes the newest message (not deterministic)",
        ),
        Parameter(
            "transport",
            Str(TRANSPORTS),
            default=AUTO,
            description="rclpy: a real rclpy node on your ROS 2's middleware (Fast DDS by default); zenoh: "
            "rmw_zenoh's wire through its router; auto: rclpy if a Python here imports it",
        ),
        Parameter(
            "python",
            Str(hint="a Python that imports rclpy, e.g. /opt/venvs/ros/bin/python"),
            default=None,
            description="rclpy: the Python to run the node with (default: ZENORBIT_ROS2_PYTHON, else this "
            "Python, else python3 on the PATH)",
        ),
        Parameter(
            "endpoint",
            Str(pattern=ENDPOINT, hint="a Zenoh endpoint like tcp/localhost:7447"),
            default=DEFAULT_ENDPOINT,
            description="zenoh: the ROS side's Zenoh router (rmw_zenohd's default)",
        ),
        Parameter(
            "domain_id",
            Int(minimum=0),
            default=DEFAULT_DOMAIN_ID,
            description="the ROS domain (ROS_DOMAIN_ID; ROS's default 0)",
        ),
        Parameter(
            "node",
            Str(pattern=r"[A-Za-z][A-Za-z0-9_]*", hint="a ROS node name (letters, digits, _)"),
            default="zenorbit_bridge",
            description="the bridge's node name in the ROS graph",
        ),
        Parameter(
            "namespace",
            Str(pattern=r"/|(/[A-Za-z][A-Za-z0-9_]*)+", hint="a ROS namespace such as /robot"),
            default="/",
            description="the node's namespace",
        ),
        Parameter(
            "timeout",
            Duration(),
            default="5 s",
            description="wall time a step waits for the node (stamped), and to reach the router; keep it "
            "below run.step_timeout so the error names the topic",
        ),
        Parameter(
            "clock",
            Bool(),
            default=True,
            description="publish /clock (rosgraph_msgs/Clock) at each step, for nodes with use_sim_time",
        ),
        Parameter(
            "outputs",
            MapOf(OUTPUT, "variable", key_pattern=VARIABLE_NAME),
            default={},
            description="output variable -> the ROS 2 topic field it is read from",
        ),
        Parameter(
            "inputs",
            MapOf(INPUT, "variable", key_pattern=VARIABLE_NAME),
            default={},
            description="input variable -> the ROS 2 topic field it is published as",
        ),
    )

    @classmethod
    def validate(cls, params, run):
        if not params["outputs"] and not params["inputs"]:
            raise ConfigError("outputs", "the bridge has no variable: declare outputs (read from ROS 2) or inputs")
        bindings(params)
        if params["transport"] == RCLPY:  # auto falls back to zenoh; rclpy asked for must be there
            try:
                choose(RCLPY, params["python"])
            except ComponentError as e:
                raise ConfigError("transport", str(e)) from None
        return params

    @classmethod
    def declare(cls, params, run):
        return [
            Variable(
                b.variable, b.causality, b.shape, b.unit, b.start, f"{b.topic} ({b.message.msgtype}.{b.field.name})"
            )
            for b in bindings(params)
        ]

    @classmethod
    def state_problem(cls, params, run):
        return (
            "ros2.bridge: the ROS 2 node's state lives outside the run, so a restart or a swap cannot "
            "take it back to a checkpoint"
        )

    @classmethod
    def group_problem(cls, params, run):
        return "ros2.bridge waits for a ROS 2 node within its steps: it would hold up the group's other members"

    def __init__(self, params, run):
        from rosbags.typesys import Stores, get_typestore

        super().__init__(params, run)
        self.bindings = bindings(params)
        self.typestore = get_typestore(Stores.ROS2_JAZZY)
        self.types = self.typestore.types
        self.epoch_ns = epoch_ns(run.epoch)
        self.wait_for = params["wait_for"]
        self.domain_id, self.endpoint = params["domain_id"], params["endpoint"]
        self.timeout_s = params["timeout"] / NS_PER_S
        self.outputs = [b for b in self.bindings if b.causality == "output"]
        self.published: dict[str, list[Binding]] = {}  # topic -> its input variables
        for b in self.bindings:
            if b.causality == "input":
                self.published.setdefault(b.topic, []).append(b)
        self.last = {b.variable: b.start.copy() for b in self.outputs}
        listened = {b.topic: b.message for b in self.outputs}
        self.listened = {topic: message.msgtype for topic, message in listened.items()}
        self.arrivals = lockstep.Arrivals({t: m.stamped for t, m in listened.items()})
        self.session: zenoh.Session | None = None  # the zenoh transport's
        self.node: RclpyNode | Node | None = None
        self._open(params, listened)

    def _open(self, params, listened: dict[str, messages.MessageMap]) -> None:
        """The ROS side (an rclpy node in a process of its own, or a Zenoh session linked to the
        router), the node, its publishers and subscribers."""
        self.transport, python, why = choose(params["transport"], params["python"])
        print(f"{params['node']}: {why}", file=sys.stderr, flush=True)
        if self.transport == RCLPY:  # then choose named a Python that imports rclpy
            self.node = RclpyNode(cast(str, python), params["domain_id"], params["node"], params["namespace"])
        else:
            self.node = self._zenoh_node(params)
        self.clock = self.node.publisher(CLOCK_TOPIC, CLOCK_TYPE, self.typestore) if params["clock"] else None
        self.publishers = {
            topic: self.node.publisher(topic, group[0].message.msgtype, self.typestore)
            for topic, group in self.published.items()
        }
        for topic, message in listened.items():
            self.node.subscriber(topic, message.msgtype, self.typestore, self._receiver(topic, message.stamped))

    def _zenoh_node(self, params):
        import zenoh

        from components.bus import session_config
        from components.ros2.rmw_zenoh import Node

        # as rmw_zenoh's nodes: a peer linked to the router, listening on localhost for the peers it learns of
        config = session_config(["tcp/localhost:0"], [params["endpoint"]], mesh=True)
        config.insert_json5("connect/timeout_ms", str(int(self.timeout_s * 1000)))
        config.insert_json5("connect/exit_on_failure", "true")
        try:
            self.session = zenoh.open(config)
        except zenoh.ZError:
            raise ComponentError(
                f"cannot reach the ROS 2 router at {params['endpoint']} within {self.timeout_s:g} s "
                f"(endpoint sets where): {hint('transport: rclpy')}"
            ) from None
        return Node(self.session, params["domain_id"], params["node"], params["namespace"])

    def _receiver(self, topic: str, stamped: bool):
        arrivals = self.arrivals

        def on_message(cdr: bytes, attachment) -> None:  # on Zenoh's thread: store only
            try:
                stamp = messages.cdr_stamp(cdr) if stamped else None
            except ValueError as e:
                print(f"warning: {topic}: dropped a message: {e}", file=sys.stderr, flush=True)
                return
            arrivals.put(topic, stamp, cdr)

        return on_message

    def initialize(self, t0_ns, inputs):
        self._await_graph()
        self._publish_clock(self.epoch_ns + t0_ns)
        return dict(self.last)

    def _await_graph(self) -> None:
        """Wait (up to ``timeout``) until another node subscribes to each input topic and publishes
        each output topic with the bridge's types: an input published before its subscriber is known
        would be lost, and its step never answered."""
        if self.transport == RCLPY:
            self._await_matches()
        else:
            self._await_tokens()

    def _await_matches(self) -> None:
        """rclpy: until the middleware has matched each of the bridge's publishers and subscriptions."""
        node = cast(RclpyNode, self.node)  # the rclpy transport's
        deadline = time.monotonic() + self.timeout_s
        while missing := node.unmatched(self.timeout_s, exclude=(CLOCK_TOPIC,)):
            if self.arrivals.interrupted:
                raise lockstep.Interrupted("the run is ending: stopped waiting for the ROS graph")
            if time.monotonic() > deadline:
                role, topic, msgtype = missing[0]
                other_types = [
                    f"{other} has it as {node_type}"
                    for _, _, node_type, other in node.graph([topic], self.timeout_s)
                    if node_type != msgtype
                ]
                wrong = f"; {other_types[0]}" if other_types else ""
                role = "subscribes to" if role == "publisher" else "publishes"
                raise ComponentError(
                    f"no ROS 2 node {role} {topic} ({msgtype}) in domain {self.domain_id} "
                    f"({node.rmw}) within {self.timeout_s:g} s{wrong}: start the node before "
                    f"the run, with the same ROS_DOMAIN_ID and RMW_IMPLEMENTATION (or raise timeout)"
                )
            time.sleep(0.02)

    def _await_tokens(self) -> None:
        """zenoh: until rmw_zenoh's liveliness tokens show the other side of each topic."""
        wanted = {
            (SUBSCRIPTION, topic, dds_type_name(group[0].message.msgtype)) for topic, group in self.published.items()
        }
        wanted |= {(PUBLISHER, topic, dds_type_name(msgtype)) for topic, msgtype in self.listened.items()}
        session = cast("zenoh.Session", self.session)  # the zenoh transport's
        own = str(session.info.zid())
        deadline = time.monotonic() + self.timeout_s
        while True:
            seen = set()
            for reply in session.liveliness().get(f"{ADMIN_SPACE}/{self.domain_id}/**", timeout=self.timeout_s):
                if reply.ok is not None:
                    parts = str(reply.ok.key_expr).split("/")
                    if len(parts) >= 11 and parts[2] != own:
                        seen.add((parts[5], parts[9].replace("%", "/"), parts[10].replace("%", "/")))
            missing = sorted(wanted - seen)
            if not missing:
                return
            if self.arrivals.interrupted:
                raise lockstep.Interrupted("the run is ending: stopped waiting for the ROS graph")
            if time.monotonic() > deadline:
                kind, topic, dds_type = missing[0]
                role = "subscribes to" if kind == SUBSCRIPTION else "publishes"
                raise ComponentError(
                    f"no ROS 2 node {role} {topic} ({dds_type}) in domain {self.domain_id} at "
                    f"{self.endpoint} within {self.timeout_s:g} s: start the node before the run "
                    f"(or raise timeout)" + ("" if seen else f"; {hint('transport: rclpy')}")
                )
            time.sleep(0.05)

    def do_step(self, t_ns, h_ns, inputs):
        stamp = self.epoch_ns + t_ns
        self._publish_clock(stamp)
        if self.wait_for == lockstep.STAMPED:
            self.arrivals.expect()
        for topic, group in self.published.items():
            first = group[0]
            values = {b.field.name: np.asarray(inputs[b.variable], dtype=np.float64).ravel() for b in group}
            names = next((b.names for b in group if b.names), ())
            message = first.message.build(self.types, stamp, first.frame_id, names, values)
            self.publishers[topic].put(bytes(self.typestore.serialize_cdr(message, first.message.msgtype)), stamp)
        if self.wait_for == lockstep.STAMPED:
            taken = self.arrivals.take_stamped(stamp, self.timeout_s) if self.outputs else {}
        else:
            taken = self.arrivals.take_latest()
        cdrs = cast("dict[str, bytes]", taken)  # what the receivers put: a message's CDR bytes
        decoded = {topic: self.typestore.deserialize_cdr(cdr, self.listened[topic]) for topic, cdr in cdrs.items()}
        for b in self.outputs:
            if b.topic in decoded:
                self.last[b.variable] = self._value(b, decoded[b.topic])
        return self.last

    def _value(self, b: Binding, message) -> np.ndarray:
        try:
            values = messages.read(b.message, b.field.name, message, list(b.names) if b.names else None)
        except ComponentError as e:
            raise ComponentError(f"{b.topic}: {e}") from None
        size = int(np.prod(b.shape)) if b.shape else 1
        if values.size != size:
            raise ComponentError(
                f"{b.topic}: {b.message.msgtype}.{b.field.name} holds {values.size} values, "
                f"output {b.variable} has {size}"
            )
        return values.reshape(b.shape)

    def _publish_clock(self, stamp: int) -> None:
        if self.clock is not None:
            clock = self.types[CLOCK_TYPE](clock=messages.ros_time(self.types, stamp))
            self.clock.put(bytes(self.typestore.serialize_cdr(clock, CLOCK_TYPE)), stamp)

    def interrupt(self):
        self.arrivals.interrupt()

    def terminate(self):
        if self.node is not None:
            self.node.close()
            self.node = None
        if self.session is not None:
            self.session.close()
            self.session = None
