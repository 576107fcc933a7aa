"""The wire protocol between the orchestrator and component processes, over Zenoh.

Star topology: the orchestrator talks to each component; components never talk to each other.
Keys, under ``zenorbit/<run_id>/``:

| key | from -> to | payload |
|---|---|---|
| ``c/<name>/<gen>/cmd`` | orchestrator -> component | control (JSON + blob) or step (binary inputs) |
| ``c/<name>/<gen>/out`` | component -> orchestrator | reply (JSON + blob), step outputs (binary) or error |
| ``alive/<name>/<gen>`` | component | liveliness token, gone when the process dies |
| ``alive/orchestrator`` | orchestrator | liveliness token; components exit when it goes |
| ``signals`` | orchestrator -> observers | one recorded row per step (binary), may drop |
| ``ctl`` | CLI -> orchestrator | queryable: status, stop, swap |

Control and step messages share one FIFO channel per component, so their order is kept (a
``get_state`` issued after step k sees the state after step k). Step payloads are raw float64
in the layout that ``describe`` fixes; no JSON per step.
"""
from __future__ import annotations

import io
import json
import struct
from typing import Any, Mapping

import numpy as np

ROOT = "zenorbit"

# message kinds (first byte)
STEP = b"S"      # orchestrator -> component: header + inputs
CONTROL = b"C"   # orchestrator -> component: JSON + blob
OUTPUT = b"O"    # component -> orchestrator: header + outputs
REPLY = b"R"     # component -> orchestrator: JSON + blob
FAULT = b"E"     # component -> orchestrator: JSON {op, k, error}
QUIT = b"Q"      # a component to itself, when the orchestrator's liveliness token is gone

_STEP_HEADER = struct.Struct("<qqq")     # k, t_ns, h_ns
_OUTPUT_HEADER = struct.Struct("<qd")    # k, compute seconds (for --profile only)
_JSON_LENGTH = struct.Struct("<I")


def run_key(run_id: str, *parts: str) -> str:
    return "/".join((ROOT, run_id, *parts))


def component_key(run_id: str, name: str, generation: int, leaf: str) -> str:
    return run_key(run_id, "c", name, str(generation), leaf)


def encode_step(k: int, t_ns: int, h_ns: int, inputs: np.ndarray) -> bytes:
    return STEP + _STEP_HEADER.pack(k, t_ns, h_ns) + inputs.tobytes()


def decode_step(payload: bytes) -> tuple[int, int, int, np.ndarray]:
    k, t_ns, h_ns = _STEP_HEADER.unpack_from(payload, 1)
    return k, t_ns, h_ns, np.frombuffer(payload, dtype=np.float64, offset=1 + _STEP_HEADER.size)


def encode_output(k: int, compute_s: float, outputs: np.ndarray) -> bytes:
    return OUTPUT + _OUTPUT_HEADER.pack(k, compute_s) + outputs.tobytes()


def decode_output(payload: bytes) -> tuple[int, float, np.ndarray]:
    k, compute_s = _OUTPUT_HEADER.unpack_from(payload, 1)
    return k, compute_s, np.frombuffer(payload, dtype=np.float64, offset=1 + _OUTPUT_HEADER.size)


def encode_message(kind: bytes, body: Mapping[str, Any], blob: bytes = b"") -> bytes:
    text = json.dumps(body).encode()
    return kind + _JSON_LENGTH.pack(len(text)) + text + blob


def decode_message(payload: bytes) -> tuple[dict, bytes]:
    (n,) = _JSON_LENGTH.unpack_from(payload, 1)
    start = 1 + _JSON_LENGTH.size
    return json.loads(payload[start:start + n]), payload[start + n:]


def encode_state(state: Mapping[str, Any]) -> bytes:
    """A component state (dict of arrays/scalars) as .npz bytes: exact, no pickles."""
    buffer = io.BytesIO()
    np.savez(buffer, **{k: np.asarray(v) for k, v in state.items()})
    return buffer.getvalue()


def decode_state(blob: bytes) -> dict[str, np.ndarray]:
    with np.load(io.BytesIO(blob), allow_pickle=False) as data:
        return {k: data[k] for k in data.files}


def session_config(listen: list[str] = (), connect: list[str] = ()):
    """A Zenoh peer config: explicit endpoints only, multicast and gossip scouting off."""
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    config.insert_json5("connect/endpoints", json.dumps(list(connect)))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "false")
    return config


def publisher(session, key: str, *, drop: bool = False):
    """Reliable, express publisher; BLOCK unless ``drop`` (for observers that may lag)."""
    import zenoh

    return session.declare_publisher(
        key,
        congestion_control=zenoh.CongestionControl.DROP if drop else zenoh.CongestionControl.BLOCK,
        reliability=zenoh.Reliability.RELIABLE,
        express=not drop,
    )
