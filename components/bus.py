"""A run's bus: its Zenoh sessions, and the step data on it.

Components exchange their outputs directly: each publishes its outputs once per step into the
inbox of each component it feeds. The orchestrator is off the per-step path: it grants a step
horizon, receives the outputs in batches (one wake-up per batch, not per step), records, and
watches for faults; control goes through it. Everything addressed to a component lands in its
one inbox, ``i/<name>/**``, read by one subscriber into a Zenoh FIFO: the component's main thread
takes messages there without a Python callback (no GIL hand-over per message, no wake-up when a
message is already waiting). The keys and the control messages are declared in
:mod:`components.protocol`; here the sessions, and the step data: outputs, batches, sync and
signals rows.

Every output message carries its generation and tag (the step index of the time it holds, see
:mod:`components.schedule`), so a consumer takes exactly the values meant for each step and
ignores a replaced generation. Step outputs are raw float64 in the layout ``declare`` fixes; no
JSON per step. The sessions form a mesh (gossip through the orchestrator's session): outputs go
straight from producer to consumer, one hop.
"""

from __future__ import annotations

import datetime as dt
import io
import json
import os
import struct
import tempfile
import threading
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from components import protocol
from components.protocol import BATCH, FRAME, FRAME_DTYPES, OUTPUT, SYNC, VIEW_FRAME, Malformed

_OUTPUT_HEADER = struct.Struct("<qq")  # generation, tag
_BATCH_HEADER = struct.Struct("<qqq")  # generation, number of steps, outputs per step
_INT = struct.Struct("<q")
# a frame's header: generation, tag, dtype (index in FRAME_DTYPES), ndim, H, W, C (1 when 2-D),
# length of the output's name (UTF-8, after the header); the raw bytes follow the name
_FRAME_HEADER = struct.Struct("<qqBBIIIH")


def count_drop(counts: dict[str, int], key: str) -> int | None:
    """Count a message dropped from ``key``; the count when it is worth a warning (the 1st, 2nd,
    4th, 8th... from each key, so a flood does not flood the log), else None."""
    n = counts[key] = counts.get(key, 0) + 1
    return n if n & (n - 1) == 0 else None


def _expect(payload: bytes | memoryview, kind: bytes, minimum: int) -> None:
    if len(payload) < minimum or payload[:1] != kind:
        raise Malformed(
            f"expected a {kind.decode()} message of at least {minimum} bytes, got {len(payload)} "
            f"bytes starting {bytes(payload[:1])!r}"
        )


def run_key(run_id: str, *parts: str) -> str:
    return "/".join((protocol.ROOT, run_id, *parts))


def command_key(run_id: str, name: str, generation: int) -> str:
    return protocol.COMMANDS.key(run_id, name=name, generation=generation)


def output_key(run_id: str, consumer: str, source: str) -> str:
    """Where ``source`` sends its outputs for ``consumer``."""
    return protocol.OUTPUTS.key(run_id, name=consumer, source=source)


def batch_key(run_id: str, name: str) -> str:
    return protocol.BATCHES.key(run_id, name=name)


def reply_key(run_id: str, name: str, generation: int) -> str:
    return protocol.REPLIES.key(run_id, name=name, generation=generation)


def quit_key(run_id: str, name: str, generation: int) -> str:
    return protocol.QUITS.key(run_id, name=name, generation=generation)


def inbox_pattern(run_id: str, name: str) -> str:
    """Everything addressed to component ``name``."""
    return protocol.INBOX.key(run_id, name=name)


def output_prefix(run_id: str, consumer: str) -> str:
    """What the keys of the outputs sent to ``consumer`` start with (then the source's name)."""
    return protocol.OUTPUTS.key(run_id, name=consumer, source="")


VIEWER = "_viewer"  # the observer's liveliness name (component names cannot start with _)
ROS2 = "_ros2"  # the ROS 2 observer's (--ros2)


def alive_key(run_id: str, name: str, generation: int) -> str:
    """The liveliness token of a component's (or the observer's, generation 0) process."""
    return protocol.ALIVE.key(run_id, name=name, generation=generation)


def orchestrator_alive_key(run_id: str) -> str:
    return protocol.ORCHESTRATOR_ALIVE.key(run_id)


def viewer_alive_key(run_id: str) -> str:
    return alive_key(run_id, VIEWER, 0)


def ros2_alive_key(run_id: str) -> str:
    return alive_key(run_id, ROS2, 0)


def control_key(run_id: str) -> str:
    """The orchestrator's queryable for the CLI."""
    return protocol.CTL.key(run_id)


def signals_key(run_id: str) -> str:
    return protocol.SIGNALS.key(run_id)


def view_key(run_id: str, name: str, output: str) -> str:
    """Where component ``name`` sends its frame output ``output`` for the live views."""
    return protocol.VIEWS.key(run_id, name=name, output=output)


# what the orchestrator subscribes to
def batch_pattern(run_id: str) -> str:
    return protocol.BATCHES.pattern(run_id)


def reply_pattern(run_id: str) -> str:
    return protocol.REPLIES.pattern(run_id)


def alive_pattern(run_id: str) -> str:
    return protocol.ALIVE.pattern(run_id)


def batch_source(key: str) -> str:
    """The component a key of :func:`batch_pattern` is from; Malformed for another key."""
    fields = protocol.BATCHES.fields(key)
    if fields is None:
        raise Malformed(f"not a component's batch key: {key!r}")
    return fields["name"]


def reply_source(key: str) -> tuple[str, int]:
    """(component, generation) of a key of :func:`reply_pattern`; Malformed for another key."""
    fields = protocol.REPLIES.fields(key)
    if fields is None or not _is_number(fields["generation"]):
        raise Malformed(f"not a component's reply key: {key!r}")
    return fields["name"], int(fields["generation"])


def alive_source(key: str) -> tuple[str, int] | None:
    """(name, generation) of a key of :func:`alive_pattern`; None for a token that is not a process's."""
    fields = protocol.ALIVE.fields(key)
    if fields is None or not _is_number(fields["generation"]):
        return None
    return fields["name"], int(fields["generation"])


def _is_number(text: str) -> bool:
    return text.isascii() and text.isdigit()  # str.isdigit alone accepts "²", which int() refuses


SIGNALS_HEADER = struct.Struct("<qd")  # a signals row: k, time in s; then one float64 per recorded column
SIGNALS_END = b"END"  # on the signals key: the run is over


def encode_output(generation: int, tag: int, outputs: np.ndarray) -> bytes:
    return OUTPUT + _OUTPUT_HEADER.pack(generation, tag) + outputs.tobytes()


def decode_output(payload: bytes) -> tuple[int, int, np.ndarray]:
    """(generation, tag, outputs); outputs a read-only view of the payload. Malformed otherwise."""
    _expect(payload, OUTPUT, 1 + _OUTPUT_HEADER.size)
    if (len(payload) - 1 - _OUTPUT_HEADER.size) % 8:
        raise Malformed(f"output message of {len(payload)} bytes: not a whole number of float64 values")
    generation, tag = _OUTPUT_HEADER.unpack_from(payload, 1)
    return generation, tag, np.frombuffer(payload, dtype=np.float64, offset=1 + _OUTPUT_HEADER.size)


def _frame_parts(generation: int, tag: int, output: str, frame: np.ndarray) -> tuple:
    name = output.encode()
    shape = frame.shape + (1,) * (3 - frame.ndim)
    header = _FRAME_HEADER.pack(generation, tag, FRAME_DTYPES.index(frame.dtype.name), frame.ndim, *shape, len(name))
    return FRAME, header, name, np.ascontiguousarray(frame).data


def encode_frame(generation: int, tag: int, output: str, frame: np.ndarray) -> bytes:
    """One frame output of one step: the header, the output's name and the array's raw bytes (C order)."""
    return b"".join(_frame_parts(generation, tag, output, frame))


def encode_view_frame(taken_ns: int, generation: int, tag: int, output: str, frame: np.ndarray) -> bytes:
    """A frame output for the live views: when it was taken (run time, ns), then its frame message."""
    return b"".join((VIEW_FRAME, _INT.pack(taken_ns), *_frame_parts(generation, tag, output, frame)))


def decode_view_frame(payload) -> tuple[int, int, int, str, np.ndarray]:
    """(taken ns, generation, tag, output, frame) of :func:`encode_view_frame`; the frame a
    read-only view of the payload. Malformed otherwise."""
    _expect(payload, VIEW_FRAME, 1 + _INT.size)
    taken = _INT.unpack_from(payload, 1)[0]
    return (taken, *decode_frame(memoryview(payload)[1 + _INT.size :]))


def decode_frame(payload: bytes | memoryview) -> tuple[int, int, str, np.ndarray]:
    """(generation, tag, output, frame); the frame a read-only view of the payload. Malformed
    unless the payload holds exactly one frame of a known dtype."""
    _expect(payload, FRAME, 1 + _FRAME_HEADER.size)
    generation, tag, dtype, ndim, h, w, c, n = _FRAME_HEADER.unpack_from(payload, 1)
    start = 1 + _FRAME_HEADER.size + n
    if dtype >= len(FRAME_DTYPES) or ndim not in (2, 3) or (ndim == 2 and c != 1):
        raise Malformed(f"frame message with dtype {dtype}, {ndim} dimensions, shape {(h, w, c)}")
    shape, dtype = (h, w, c)[:ndim], np.dtype(FRAME_DTYPES[dtype])
    if len(payload) != start + h * w * c * dtype.itemsize:
        raise Malformed(f"frame message of {len(payload)} bytes does not hold a {dtype.name} frame of shape {shape}")
    try:
        output = bytes(payload[1 + _FRAME_HEADER.size : start]).decode()
    except UnicodeDecodeError:
        raise Malformed("frame message whose output name is not UTF-8") from None
    return generation, tag, output, np.frombuffer(payload, dtype=dtype, offset=start).reshape(shape)


def encode_batch(generation: int, tags: np.ndarray, timings: np.ndarray, outputs: np.ndarray) -> bytes:
    """n steps' outputs: tags (n,) int64, timings (n, 2) compute and idle seconds, outputs (n, size)."""
    n, size = outputs.shape
    return (
        BATCH
        + _BATCH_HEADER.pack(generation, n, size)
        + tags.astype(np.int64).tobytes()
        + timings.tobytes()
        + outputs.tobytes()
    )


def decode_batch(payload: bytes) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """(generation, tags (n,), timings (n, 2), outputs (n, size)), views of the payload; Malformed
    unless the payload holds exactly that, n >= 1 steps with increasing tags."""
    _expect(payload, BATCH, 1 + _BATCH_HEADER.size)
    generation, n, size = _BATCH_HEADER.unpack_from(payload, 1)
    offset = 1 + _BATCH_HEADER.size
    if n < 1 or size < 0 or len(payload) != offset + 8 * n * (3 + size):
        raise Malformed(f"batch message of {len(payload)} bytes does not hold {n} steps of {size} outputs")
    tags = np.frombuffer(payload, dtype=np.int64, count=n, offset=offset)
    timings = np.frombuffer(payload, dtype=np.float64, count=2 * n, offset=offset + 8 * n).reshape(n, 2)
    outputs = np.frombuffer(payload, dtype=np.float64, count=n * size, offset=offset + 24 * n).reshape(n, size)
    if n > 1 and not np.all(np.diff(tags) > 0):
        raise Malformed("batch message with tags not increasing")
    return generation, tags, timings, outputs


def encode_sync(generation: int) -> bytes:
    return SYNC + _INT.pack(generation)


def decode_sync(payload: bytes) -> int:
    _expect(payload, SYNC, 1 + _INT.size)
    return _INT.unpack_from(payload, 1)[0]


def jsonable(value):
    """Parameters as JSON values for a message body: YAML gives datetimes (sent as UTC text) and
    dicts with keys of any type (sent as their str), numpy gives arrays (sent as lists)."""
    if isinstance(value, (dt.datetime, dt.date)):
        return value.isoformat().replace("+00:00", "Z")
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    return value


def encode_state(state: Mapping[str, Any]) -> bytes:
    """A component state (dict of arrays/scalars) as .npz bytes: exact, no pickles."""
    buffer = io.BytesIO()
    arrays: dict[str, Any] = {k: np.asarray(v) for k, v in state.items()}  # Any: no key is savez's allow_pickle
    np.savez(buffer, **arrays)
    return buffer.getvalue()


def decode_state(blob: bytes) -> dict[str, np.ndarray]:
    try:
        with np.load(io.BytesIO(blob), allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except Exception as e:  # np.load raises whatever its parsers meet in a corrupt file
        raise Malformed(f"state blob of {len(blob)} bytes is not an .npz archive ({type(e).__name__}: {e})") from None


SECRET_ENV = "ZENORBIT_SECRET"  # how a run's processes get its secret (never on a command line)
USER = "zenorbit"


def open_session(
    listen: Sequence[str] = (),
    connect: Sequence[str] = (),
    *,
    mesh: bool = False,
    secret: str | None = None,
    settings: dict | None = None,
    connect_timeout_s: float | None = None,
):
    """A Zenoh session (see :func:`session_config`). With ``secret``, every link to or from
    it is authenticated: Zenoh's user/password challenge-response, the secret never sent. Peers
    without it are refused; they cannot publish, subscribe or query (docs/design.md §7).
    ``settings``: the run's bus settings (TLS, access control, lease, mode:
    :mod:`components.bus_security`). ``connect_timeout_s``: fail (ZError) unless a link to one of
    ``connect`` is up within it, rather than go on trying in the background."""
    import zenoh

    from components import bus_security

    settings = settings or {}
    config = session_config(listen, connect, mesh=mesh, mode=settings.get("mode", "peer"))
    bus_security.apply(config, settings, listening=bool(listen))
    if connect and connect_timeout_s is not None:
        config.insert_json5("connect/timeout_ms", json.dumps(int(connect_timeout_s * 1000)))
        config.insert_json5("connect/exit_on_failure", "true")
    if secret is None:
        return zenoh.open(config)
    config.insert_json5("transport/auth/usrpwd/user", json.dumps(USER))
    config.insert_json5("transport/auth/usrpwd/password", json.dumps(secret))
    if not listen:  # only who accepts links checks them
        return zenoh.open(config)
    fd, path = tempfile.mkstemp(prefix="zenorbit-", suffix=".auth")  # mode 0600
    try:
        with os.fdopen(fd, "w") as file:
            file.write(f"{USER}:{secret}\n")
        config.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(path))
        return zenoh.open(config)  # reads the dictionary here, once
    finally:
        os.unlink(path)


# Zenoh's tasks (links' transmit and receive, accepting, the rest) on one thread of one runtime,
# not five runtimes of their own: a message then crosses fewer threads, and each hand-over
# between threads is a wake-up that costs tens of microseconds on a busy or virtual machine.
# Measured on 2 cores: the pub/sub round trip between two processes 0.6-0.75x, the Zenoh threads'
# CPU time per step ~0.9x (benchmarks/bench_pace.py). Every callback of ours only enqueues, so
# one thread cannot deadlock on them. A ZENOH_RUNTIME set by the user wins.
RUNTIME = (
    "(app: (worker_threads: 1), rx: (handover: app), tx: (handover: app), acc: (handover: app), net: (handover: app))"
)
# The same, but the links' transmit on a thread of its own: for a process whose Zenoh thread may
# itself block sending (congestion control BLOCK from a Zenoh task, as an AdvancedPublisher's
# cache answering a late joiner). On the one thread of RUNTIME that wait holds up the very task
# that would drain the queue: a deadlock until the link is closed (block/wait_before_close).
RUNTIME_OWN_TX = "(app: (worker_threads: 1), rx: (handover: app), tx: (worker_threads: 1), acc: (handover: app), net: (handover: app))"
DEFAULT_RUNTIME = "()"  # Zenoh's own: a runtime per task kind


def prefer_runtime(runtime: str) -> None:
    """Have this process's Zenoh run on ``runtime`` (call before its first session), unless the
    user set ZENOH_RUNTIME: RUNTIME in the environment is inherited from a process of ours
    (:func:`session_config` sets it), not the user's choice, and is replaced too."""
    if os.environ.get("ZENOH_RUNTIME", RUNTIME) == RUNTIME:
        os.environ["ZENOH_RUNTIME"] = runtime


def session_config(listen: Sequence[str] = (), connect: Sequence[str] = (), *, mesh: bool = False, mode: str = "peer"):
    """A Zenoh config: explicit endpoints, no multicast scouting; ``mode`` peer, client or router;
    Zenoh's runtime as ``RUNTIME`` in a process that has not started it yet.

    ``mesh``: gossip on, so the peers of a run (all connected to the orchestrator's session)
    learn each other's listen endpoints and connect directly; a run never meets another run's
    peers, since nothing connects the two meshes.
    """
    import zenoh

    os.environ.setdefault("ZENOH_RUNTIME", RUNTIME)  # read once, when the first session starts Zenoh's runtime

    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    config.insert_json5("connect/endpoints", json.dumps(list(connect)))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "true" if mesh or mode == "router" else "false")
    # one side of each pair connects: with authentication, two links opened at once may both be refused
    config.insert_json5("scouting/gossip/autoconnect_strategy", '{peer: {to_router: "always", to_peer: "greater-zid"}}')
    return config


CLOSE_WAIT_S = 2.0


def close_session(session, wait_s: float = CLOSE_WAIT_S) -> None:
    """Close a Zenoh session, waiting at most ``wait_s`` seconds: Zenoh sends each link a close
    and waits for it to drain, which on a cut link (a pulled cable: nothing acknowledged) takes
    ~17 s. A close not done by then goes on in a daemon thread and the links go with the process
    (so Ctrl-C on a component whose link was cut ends it at once)."""
    import zenoh

    def close() -> None:
        try:
            session.close()
        except zenoh.ZError:  # a link that cannot be closed cleanly: it goes with the process
            pass

    closer = threading.Thread(target=close, name="zenorbit-close", daemon=True)
    closer.start()
    closer.join(wait_s)


def listen_beside(connect: str) -> str:
    """A listen endpoint with a free port on the host used to reach ``connect``'s side: loopback
    for a local orchestrator, every interface otherwise."""
    proto, _, address = connect.partition("/")
    host = address.rpartition(":")[0]
    local = host in ("127.0.0.1", "localhost", "[::1]")
    return f"{proto}/{'127.0.0.1' if local else '0.0.0.0'}:0"


def open_view_session(connect: str, secret: str | None, settings: dict | None):
    """A live view's session: a peer of the run's mesh (listening beside ``connect``, gossip on),
    since peers do not route for each other and the components' frames (``VIEWS``) come straight
    from them; in the settings' mode ``client``, a client of the run's router."""
    settings = settings or {}
    peer = settings.get("mode", "peer") == "peer"
    return open_session(
        [listen_beside(connect)] if peer else [], [connect], mesh=peer, secret=secret, settings=settings
    )


def publisher(session, key: str, *, drop: bool = False):
    """Reliable, express publisher; BLOCK unless ``drop`` (for observers that may lag)."""
    import zenoh

    return session.declare_publisher(
        key,
        congestion_control=zenoh.CongestionControl.DROP if drop else zenoh.CongestionControl.BLOCK,
        reliability=zenoh.Reliability.RELIABLE,
        express=not drop,
    )
