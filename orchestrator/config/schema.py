"""The run config's keys, declared once as schema records (types, defaults, units, descriptions):
validation reads them and docs/design.md's tables are generated from them."""

from __future__ import annotations

from pathlib import Path

from components.schedule import ALGORITHMS
from components.schema import (
    Anything,
    Bool,
    Duration,
    Float,
    Int,
    ListOf,
    MapOf,
    OneOf,
    Parameter,
    Record,
    Str,
    UtcTime,
    markdown,
)

MAX_STEPS = 10**12  # steps in a run: beyond, a typo (a duration in the wrong unit), not an experiment
VIEWER_MODES = ("spawn", "web", "save", "foxglove", "off")
FOXGLOVE_PORT = 8765  # the Foxglove app's default WebSocket port
ROS2_ENDPOINT = "tcp/localhost:7447"  # rmw_zenohd's default listen endpoint
ROS2_TRANSPORTS = ("auto", "rclpy", "zenoh")  # components/ros2/rclpy_transport.py
ROS2_DISTROS = ("jazzy", "kilted", "lyrical")  # rmw_zenoh with type hashes in its keys (Jazzy and later)
NAME = r"[A-Za-z][A-Za-z0-9_]*"
# plausible (a warning beyond, in s and Hz): a step from a microsecond (a fast loop) to an hour (an
# orbit alone); a live view's rate from a frame a minute to a kHz
STEP = (1e-6, 3600.0)
RATE = (1 / 60, 1e3)
ENDPOINT = r"(tcp|udp|tls|quic)/(\[[0-9a-fA-F:]+\]|[A-Za-z0-9.\-]+):\d{1,5}"

RUN = Record(
    "run",
    (
        Parameter(
            "name",
            Str(pattern=r"[A-Za-z0-9][A-Za-z0-9_\-]*", hint="letters, digits, '_' or '-'"),
            description="the run's name: its recording folder and bus keys",
        ),
        Parameter("epoch", UtcTime(), description="UTC time of t = 0, e.g. 2022-09-18T12:00:00Z"),
        Parameter("duration", Duration(), description="simulated time, a whole number of steps"),
        Parameter(
            "step", Duration(plausible=STEP), description="communication step; components may take multiples of it"
        ),
        Parameter(
            "algorithm",
            Str(ALGORITHMS),
            default="jacobi",
            description="jacobi: all step on the last outputs; gauss-seidel: in config order, on the newest",
        ),
        Parameter(
            "realtime",
            Float(minimum=0.0),
            default=0.0,
            description="0: as fast as possible; k: paced at k times the wall clock",
        ),
        Parameter(
            "step_timeout",
            Duration(plausible=(0.1, 86400.0)),
            default="10 s",
            description="wall time a component may take for one step before the run fails",
        ),
        Parameter(
            "start_timeout",
            Duration(plausible=(1.0, 86400.0)),
            default="3 min",
            description="wall time a component may take to start and initialize (a first run on a "
            "machine compiles the kernels: 20-45 s on 2 cores)",
        ),
        Parameter(
            "join_timeout",
            Duration(plausible=(1.0, 7 * 86400.0)),
            default="5 min",
            description="wall time a launch: external component may take to join (orchestrator join), "
            "and to join again after it was lost",
        ),
        Parameter(
            "checkpoint_every",
            Duration(),
            default=None,
            description="simulated time between checkpoints, when a component has on_failure: restart "
            "(none: the start is the only one)",
        ),
        Parameter(
            "max_restarts",
            Int(minimum=0),
            default=3,
            description="restarts from a checkpoint before a failure ends the run",
        ),
        Parameter(
            "record_flush",
            Duration(plausible=(1e-3, 3600.0)),
            default="1 s",
            description="wall time at most between the recording's writes to disk (besides every 1000 rows): "
            "a full disk or a kill loses no more than this",
        ),
        Parameter(
            "strict",
            Bool(),
            default=False,
            description="true: the check's warnings (a value outside its plausible range, suspect physics) are "
            "errors, as with --strict",
        ),
        Parameter(
            "expect",
            Str(pattern=NAME, hint="an outcome's name, e.g. captured"),
            default=None,
            description="the outcome the run must come to (one its components declare, e.g. captured): another "
            "ends it with exit code 3 (orchestrator run --expect NAME overrides it)",
        ),
        Parameter(
            "packages",
            MapOf(Str(hint="a directory"), "package name"),
            default={},
            description="ROS packages by name -> directory (relative to the config file), for package:// URIs "
            "and $(find NAME) in URDFs; looked up before ROS_PACKAGE_PATH and installed packages",
        ),
    ),
    description="the run's identity and timing (``run:``)",
)
BUS = Record(
    "bus",
    (
        Parameter(
            "listen",
            ListOf(Str(pattern=ENDPOINT, hint="a Zenoh endpoint like tcp/127.0.0.1:0"), min_items=1),
            default=["tcp/127.0.0.1:0"],
            description="where the orchestrator listens (loopback by default; "
            "another address is for components on other hosts)",
        ),
        Parameter(
            "connect",
            ListOf(Str(pattern=ENDPOINT, hint="a Zenoh endpoint like tcp/192.0.2.7:7447")),
            default=[],
            description="endpoints the orchestrator links to besides the router (other peers)",
        ),
        Parameter(
            "mode",
            Str(("peer", "client")),
            default="peer",
            description="peer: the run's processes link to each other directly; client: everything goes "
            "through bus.router",
        ),
        Parameter(
            "router",
            Str(pattern=ENDPOINT, hint="a Zenoh endpoint like tcp/192.0.2.7:7447"),
            default=None,
            description="a router every process of the run links to (orchestrator router), for hosts that "
            "cannot reach each other",
        ),
        Parameter(
            "lease",
            Duration(plausible=(0.1, 3600.0)),
            default="10 s",
            description="a link silent this long counts as dead: its component is lost (keep-alives every quarter)",
        ),
        Parameter(
            "tls",
            OneOf((Bool(), Str(("auto",)))),
            default="auto",
            description="mutual TLS on every link (true | false); auto: on when the bus leaves loopback "
            "(bus.listen, bus.connect or bus.router)",
        ),
        Parameter(
            "plaintext",
            Str(("refuse", "accept-the-risk")),
            default="refuse",
            description="tls: false with the bus beyond loopback is refused unless this says accept-the-risk "
            "(then every process listens in plain TCP, and the run warns at start)",
        ),
        Parameter(
            "ca",
            Record(
                "ca",
                (
                    Parameter("certificate", Str(hint="a PEM file"), description="the CA's certificate (PEM)"),
                    Parameter("key", Str(hint="a PEM file"), description="its private key (PEM)"),
                ),
                description="your CA, to issue the run's certificates (``bus.ca``)",
            ),
            default=None,
            description="issue the run's certificates from your CA (default: a CA made for the run)",
        ),
    ),
    description="the Zenoh bus (``bus:``)",
)
VIEWER = Record(
    "viewer",
    (
        Parameter(
            "mode",
            Str(VIEWER_MODES),
            description="spawn a Rerun viewer, serve it on the web, save a .rrd, "
            "serve the run to Foxglove (WebSocket), or off",
        ),
        Parameter(
            "file",
            Str(pattern=r".+\.rrd", hint="a file name ending in .rrd"),
            default=None,
            description="the recording of save, relative to the config file",
        ),
        Parameter(
            "rate",
            Float("Hz", positive=True, plausible=RATE),
            default=30.0,
            description="rows drawn per second of simulated time, as every n-th step, n = round(1 / (rate * "
            "run.step)), at least 1: 30 Hz at a 10 ms step is every 3rd, 33.3 a second",
        ),
        Parameter("open_browser", Bool(), default=False, description="web: open the viewer in a browser"),
        Parameter(
            "port",
            Int(minimum=1),
            default=FOXGLOVE_PORT,
            description="foxglove: the WebSocket port on localhost (ws://localhost:PORT)",
        ),
    ),
    description="the live view, in Rerun or Foxglove (``viewer:``, or ``--view``)",
)
ROS2 = Record(
    "ros2",
    (
        Parameter(
            "transport",
            Str(ROS2_TRANSPORTS),
            default="auto",
            description="rclpy: a real rclpy node on the middleware your ROS 2 environment selects (Fast DDS "
            "by default); zenoh: rmw_zenoh's wire through its router, no ROS install needed; auto: "
            "rclpy if a Python here imports it, else zenoh",
        ),
        Parameter(
            "python",
            Str(hint="a Python interpreter that imports rclpy, e.g. /opt/venvs/ros/bin/python"),
            default=None,
            description="rclpy: the Python to run the node with (default: ZENORBIT_ROS2_PYTHON, "
            "else this Python, else python3 on the PATH)",
        ),
        Parameter(
            "endpoint",
            Str(pattern=ENDPOINT, hint="a Zenoh endpoint like tcp/localhost:7447"),
            default=ROS2_ENDPOINT,
            description="zenoh: the ROS side's Zenoh router (rmw_zenohd, or orchestrator router --ros2)",
        ),
        Parameter(
            "domain_id",
            Int(minimum=0),
            default=None,
            description="the ROS domain (default: the environment's ROS_DOMAIN_ID, else 0)",
        ),
        Parameter(
            "distro",
            Str(ROS2_DISTROS),
            default="jazzy",
            description="the ROS 2 distribution whose message definitions and type hashes are used",
        ),
        Parameter(
            "topics",
            ListOf(Str(hint="a topic name like /clock"), unique=True),
            default=None,
            description="the topics published, by name as orchestrator export --rosbag2 writes them (default: all)",
        ),
        Parameter(
            "rate",
            Float("Hz", positive=True, plausible=RATE),
            default=30.0,
            description="rows published per second of simulated time, as every n-th step, n = round(1 / "
            "(rate * run.step)), at least 1 (30 Hz at a 10 ms step: every 3rd, 33.3 a second; with a "
            "viewer, the higher of the two rates)",
        ),
    ),
    description="the live ROS 2 view, over rclpy or rmw_zenoh (``ros2:``, or ``--ros2 [TRANSPORT|ENDPOINT]``)",
)
SHADOW = Record(
    "shadow",
    (
        Parameter(
            "type",
            Str(hint="a component type name"),
            description="any type with the component's connected inputs and all its outputs, same shapes and units",
        ),
        Parameter(
            "parameters", Anything(), default={}, description="the type's parameters (orchestrator describe TYPE)"
        ),
    ),
    description="a second instance on the component's inputs at every step, in a process of its own; recorded "
    "as ``<component>_shadow.<output>``, it feeds nothing (``components.<name>.shadow``)",
)
COMPONENT = Record(
    "component",
    (
        Parameter(
            "type",
            Str(hint="a component type name"),
            description="a built-in type (orchestrator types), module:Class or file.py:Class",
        ),
        Parameter(
            "step",
            Duration(plausible=STEP),
            default=None,
            description="its step, a multiple of run.step (default: run.step)",
        ),
        Parameter(
            "parameters", Anything(), default={}, description="the type's parameters (orchestrator describe TYPE)"
        ),
        Parameter(
            "launch",
            Str(("local", "external")),
            default="local",
            description="local: the orchestrator starts it; external: you do (orchestrator ps prints how)",
        ),
        Parameter(
            "dedicated_cpu",
            OneOf((Bool(), Str(("process",)))),
            default=False,
            description="true: its stepping thread on a CPU of its own, for a component that computes most of "
            "each step; process: its whole process there, its bus threads too, for one that waits "
            "for its inputs much of each step (speed only, never results)",
        ),
        Parameter(
            "on_failure",
            Str(("stop", "restart")),
            default="stop",
            description="when it dies or hangs: stop the run, or restart the run from its last checkpoint",
        ),
        Parameter(
            "process",
            Str(pattern=NAME, hint="a group name: a letter, then letters, digits or '_'"),
            default=None,
            description="a group name: every component naming it runs in one process, their outputs to each "
            "other in memory (speed only, never results; default: a process of its own)",
        ),
        Parameter(
            "shadow",
            SHADOW,
            default=None,
            description="a second instance run beside it on the same inputs, recorded, never fed back",
        ),
    ),
    description="one component (``components.<name>``)",
)
EVENT = Record(
    "event",
    (
        Parameter("at", Duration(positive=False), description="simulated time of the swap, on a step of the component"),
        Parameter("swap", Str(), description="the component replaced"),
        Parameter(
            "type", Str(hint="a component type name"), default=None, description="the new type (default: the same)"
        ),
        Parameter(
            "parameters",
            Anything(),
            default=None,
            description="the new parameters (default: the old ones when the state is handed over: the same "
            "type or one that takes its state; none for another)",
        ),
    ),
    description="a swap during the run (``events:``)",
)
FAULT_KINDS = ("crash", "hang", "nan", "delay")
FAULT = Record(
    "fault",
    (
        Parameter(
            "at", Duration(positive=False), description="simulated time: the component's first step at or after it"
        ),
        Parameter("component", Str(), description="the component that fails"),
        Parameter(
            "kind",
            Str(FAULT_KINDS),
            description="crash: SIGKILL; hang: never finishes the step; "
            "nan: a NaN output; delay: the step takes longer",
        ),
        Parameter("duration", Duration(), default=None, description="delay: the wall time the step is held"),
    ),
    description="an injected failure, once per run (``faults:``)",
)
CONFIG = Record(
    "config",
    (
        Parameter("run", RUN, description="identity and timing"),
        Parameter(
            "components", MapOf(COMPONENT, "component name", key_pattern=NAME), description="the components by name"
        ),
        Parameter(
            "connections",
            MapOf(Str(hint="'<component>.<output>'"), "input"),
            default={},
            description="'<component>.<input>: <component>.<output>'",
        ),
        Parameter("bus", BUS, default={}, description="the Zenoh bus"),
        Parameter("events", ListOf(EVENT), default=[], description="swaps during the run"),
        Parameter("faults", ListOf(FAULT), default=[], description="injected failures, to test a setup's recovery"),
        Parameter("viewer", VIEWER, default=None, description="the live view (Rerun or Foxglove)"),
        Parameter("ros2", ROS2, default=None, description="the live ROS 2 view, over rclpy or rmw_zenoh"),
    ),
    description="a run config",
)


DOCS_START = "<!-- config reference: python -m orchestrator.config --docs -->"
DOCS_END = "<!-- end of config reference -->"
DESIGN_DOC = Path(__file__).resolve().parents[2] / "docs" / "design.md"


def write_docs(design: Path = DESIGN_DOC) -> None:
    """Write CONFIG's tables into docs/design.md between the markers (they come from the declaration)."""
    head, rest = design.read_text().split(DOCS_START, 1)
    tail = rest.split(DOCS_END, 1)[1]
    design.write_text(f"{head}{DOCS_START}\n{markdown(CONFIG)}\n{DOCS_END}{tail}")
