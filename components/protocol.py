"""The orchestrator-component protocol, declared once: the keys of a run and the control messages
on them. :mod:`components.bus` spells its keys with these topics and carries the step data
(outputs, batches, sync, signals rows); :mod:`components.bus_security` derives its access-control
rules from them, :mod:`orchestrator.hosts.join` its join key.

Topics, under ``zenorbit/<run_id>/``:

| topic | key | from -> to | payload |
|---|---|---|---|
| ``INBOX`` | ``i/<name>/**`` | anyone -> component | everything addressed to it: one subscriber, one FIFO |
| ``OUTPUTS`` | ``i/<name>/o/<source>`` | component -> a consumer | step outputs (binary, tagged), a batch of them, a frame, or sync |
| ``COMMANDS`` | ``i/<name>/c/<generation>`` | orchestrator -> component | the commands below |
| ``QUITS`` | ``i/<name>/q/<generation>`` | component -> itself | ``Quit``: the orchestrator's liveliness token went away |
| ``BATCHES`` | ``r/<name>`` | component -> orchestrator | a batch of step outputs (binary), for recording |
| ``REPLIES`` | ``c/<name>/<generation>/out`` | component -> orchestrator | the reports below |
| ``ALIVE`` | ``alive/<name>/<generation>`` | component | liveliness token, gone when the process dies |
| ``ORCHESTRATOR_ALIVE`` | ``alive/orchestrator`` | orchestrator | liveliness token; components exit when it goes |
| ``SIGNALS`` | ``signals`` | orchestrator -> observers | one recorded row per step (binary), may drop |
| ``VIEWS`` | ``v/<name>/<output>`` | component -> live views | a frame output of a step (``VIEW_FRAME``), may drop; sent only while a view subscribes |
| ``CTL`` | ``ctl`` | CLI -> orchestrator | queryable: status, stop, swap (:mod:`components.queries`) |
| ``JOIN`` | ``join/<name>`` | joiner -> orchestrator | queryable: which generation to serve (:mod:`components.queries`) |

Messages: a first byte says the kind; ``C``, ``R``, ``E`` and ``V`` then hold a JSON object
(length-prefixed, uint32 little-endian) and a blob (the rest), framed by
:mod:`components.message_codec`; the JSON object's ``op`` names the command, or for ``R`` and
``E`` the command answered. Times in integer ns, values float64.

| message | kind, op | topic | fields (JSON unless said) |
|---|---|---|---|
| ``Horizon`` | ``H`` | COMMANDS | ``horizon``: steps ``k < horizon`` may run (int64, binary) |
| ``Instantiate`` | ``C`` instantiate | COMMANDS | ``type``; ``params`` (the component's, with the run's) |
| ``Wire`` | ``C`` wire | COMMANDS | ``generation``; ``step_ns`` (the run step, ns); ``ratio`` (its step in run steps); ``k`` (the step it starts at); ``consumers``, ``batch_consumers`` (names); ``routes``; ``sources`` (name -> generation); ``faults`` ([step, kind, seconds] to inject); ``frame_routes`` ([source, output, input, ratio, ahead]); ``frame_consumers`` (frame output -> names) |
| ``Initialize`` | ``C`` initialize | COMMANDS | ``t0_ns``; ``input_times_ns`` (input -> when sampled, ns); blob: ``inputs`` (float64) |
| ``Sync`` | ``C`` sync | COMMANDS | (none): send sync to the consumers, reply ``synced`` once every source is heard |
| ``Start`` | ``C`` start | COMMANDS | ``held`` ([source, tag, size]); ``horizon``; blob: ``values``, the held outputs in that order (float64) |
| ``Rewire`` | ``C`` rewire | COMMANDS | ``held``, blob ``values`` as Start; ``routes``; ``sources`` |
| ``GetState`` | ``C`` get_state | COMMANDS | (none): reply with the state as the blob |
| ``SetState`` | ``C`` set_state | COMMANDS | blob: ``state`` (.npz, :func:`components.bus.encode_state`) |
| ``Terminate`` | ``C`` terminate | COMMANDS | ``final``: the run is over (else a restart may want it again) |
| ``Reply`` | ``R`` (the op answered) | REPLIES | ``details`` (more keys of the JSON object); blob |
| ``Fault`` | ``E`` (where it failed) | REPLIES | ``k`` (the failing step, < 0 outside a step); ``error`` |
| ``Events`` | ``V`` events | REPLIES | ``k`` (the step that emitted them); ``events`` ([kind, fields]) |
| ``Beat`` | ``K`` | REPLIES | (none): still here, every quarter of bus.lease |
| ``Quit`` | ``Q`` | QUITS | (none) |

Each message has one encoder (``message.encode()``) and one decoder (``Type.decode(payload)``,
or ``decode_command`` / ``decode_report`` for whatever comes on a topic); a decoder
raises :class:`Malformed` for anything but a well-formed message of its type, whose fields then
have their declared types.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

from components.message_codec import Bare, Json, Malformed, Message, OneOf, frame, from_json
from components.schedule import Route

ROOT = "zenorbit"
ORCHESTRATOR = "orchestrator"  # the orchestrator's liveliness name


# ---------------------------------------------------------------------------------------- topics


@dataclass(frozen=True)
class Topic:
    """Keys under ``zenorbit/<run_id>/``: ``template``'s chunks, each literal or a ``{field}``."""

    template: str

    def key(self, run_id: str, **fields) -> str:
        """The key with every field given (a value as its str)."""
        return self._spell(run_id, fields, None)

    def pattern(self, run_id: str, **fields) -> str:
        """A key expression of this topic's keys: the fields not given are ``*``."""
        return self._spell(run_id, fields, "*")

    def covering(self, run_id: str) -> str:
        """A key expression of every key of this topic and every key below one, for an
        access-control rule (a longer key must not slip past it): its fields ``*``, trailing
        ones ``**``."""
        chunks = self.pattern(run_id).split("/")
        if chunks[-1] != "*":
            return "/".join(chunks)
        while chunks[-1] == "*":
            chunks.pop()
        return "/".join([*chunks, "**"])

    def fields(self, key: str) -> dict[str, str] | None:
        """The fields of a key of this topic, as text (``{"name": "arm", "generation": "2"}``);
        None for a key of another form."""
        chunks, template = key.split("/"), self.template.split("/")
        if len(chunks) != len(template) + 2 or chunks[0] != ROOT:
            return None
        found = {}
        for chunk, part in zip(chunks[2:], template):
            if part.startswith("{") and chunk:
                found[part[1:-1]] = chunk
            elif chunk != part:
                return None
        return found

    def _spell(self, run_id: str, fields: dict, wildcard: str | None) -> str:
        chunks = []
        for chunk in self.template.split("/"):
            if chunk.startswith("{"):
                name = chunk[1:-1]
                if name in fields:
                    chunk = str(fields[name])
                elif wildcard is not None:
                    chunk = wildcard
                else:
                    raise TypeError(f"key of {self.template!r}: no value for {name!r} (given: {', '.join(fields)})")
            chunks.append(chunk)
        return "/".join((ROOT, run_id, *chunks))


INBOX = Topic("i/{name}/**")
OUTPUTS = Topic("i/{name}/o/{source}")
COMMANDS = Topic("i/{name}/c/{generation}")
QUITS = Topic("i/{name}/q/{generation}")
BATCHES = Topic("r/{name}")
REPLIES = Topic("c/{name}/{generation}/out")
ALIVE = Topic("alive/{name}/{generation}")
ORCHESTRATOR_ALIVE = Topic(f"alive/{ORCHESTRATOR}")
SIGNALS = Topic("signals")
VIEWS = Topic("v/{name}/{output}")
CTL = Topic("ctl")
JOIN = Topic("join/{name}")


# -------------------------------------------------------------------------------- message kinds

CONTROL = b"C"  # orchestrator -> component: a command (JSON + blob)
HORIZON = b"H"  # orchestrator -> component: steps k < horizon may run
OUTPUT = b"O"  # component -> consumers: header + outputs (components.bus)
BATCH = b"B"  # component -> orchestrator: several steps' outputs (components.bus)
FRAME_DTYPES = ("uint8", "float32")  # a frame's element types, as numpy names them (index: its code)
FRAME = b"F"  # component -> consumers: one frame output of one step (components.bus)
VIEW_FRAME = b"L"  # component -> live views: when the frame was taken, then a FRAME message (components.bus)
SYNC = b"Y"  # component -> consumers: "you hear me" (the start-up handshake, components.bus)
REPLY = b"R"  # component -> orchestrator: JSON + blob
FAULT = b"E"  # component -> orchestrator: JSON {op, k, error}
EVENT = b"V"  # component -> orchestrator: JSON {op: "events", k, events}
QUIT = b"Q"  # a component to itself, when the orchestrator's liveliness token is gone
BEAT = b"K"  # component -> orchestrator: "still here"

_INT = struct.Struct("<q")


# ------------------------------------------------------------------------------ the messages


@dataclass(frozen=True)
class Horizon(Message):
    KIND = HORIZON
    horizon: int

    def encode(self) -> bytes:
        return HORIZON + _INT.pack(self.horizon)

    @classmethod
    def decode(cls, payload: bytes) -> Horizon:
        if payload[:1] != HORIZON or len(payload) != 1 + _INT.size:
            raise Malformed(
                f"Horizon: expected {HORIZON!r} and an int64 ({1 + _INT.size} bytes), "
                f"got {len(payload)} bytes starting {bytes(payload[:1])!r}"
            )
        return cls(_INT.unpack_from(payload, 1)[0])


@dataclass(frozen=True)
class Instantiate(Message):
    KIND, OP = CONTROL, "instantiate"
    type: str
    params: dict[str, Json]
    run: dict[str, Json]  # sdk.RunSettings.to_json


@dataclass(frozen=True)
class Wire(Message):
    KIND, OP = CONTROL, "wire"
    generation: int
    step_ns: int
    ratio: int
    k: int
    consumers: list[str]
    batch_consumers: list[str]
    routes: list[Route]
    sources: dict[str, int]
    faults: list[tuple[int, str, float]]
    frame_routes: list[tuple[str, str, str, int, int]] = field(
        default_factory=list
    )  # source, output, input, ratio, ahead
    frame_consumers: dict[str, list[str]] = field(default_factory=dict)  # frame output -> consumers


@dataclass(frozen=True)
class Initialize(Message):
    KIND, OP = CONTROL, "initialize"
    t0_ns: int
    input_times_ns: dict[str, int]
    inputs: np.ndarray


class _Holding:
    """Start and Rewire: ``held`` lists [source, tag, size], ``values`` the outputs in that order."""

    held: list[tuple[str, int, int]]
    values: np.ndarray

    def check(self) -> None:
        sizes = [size for _, _, size in self.held]
        if min(sizes, default=0) < 0 or sum(sizes) != self.values.size:
            raise Malformed(
                f"{type(self).__name__}: expected held sizes >= 0 adding up to the {self.values.size} "
                f"values of the blob, got {sizes}"
            )

    def held_values(self) -> list[tuple[str, int, np.ndarray]]:
        """(source, tag, outputs) of each entry of ``held``, outputs a copy."""
        offset, entries = 0, []
        for source, tag, size in self.held:
            entries.append((source, tag, self.values[offset : offset + size].copy()))
            offset += size
        return entries


def holding(entries: list[tuple[str, int, np.ndarray]]) -> tuple[list[tuple[str, int, int]], np.ndarray]:
    """``held`` and ``values`` for Start and Rewire from (source, tag, outputs) entries."""
    vectors = [np.asarray(vector, dtype=np.float64) for _, _, vector in entries]
    return (
        [(source, tag, int(v.size)) for (source, tag, _), v in zip(entries, vectors)],
        np.concatenate(vectors) if vectors else np.empty(0),
    )


@dataclass(frozen=True)
class Start(_Holding, Message):
    KIND, OP = CONTROL, "start"
    held: list[tuple[str, int, int]]
    horizon: int
    values: np.ndarray


@dataclass(frozen=True)
class Rewire(_Holding, Message):
    KIND, OP = CONTROL, "rewire"
    held: list[tuple[str, int, int]]
    routes: list[Route]
    sources: dict[str, int]
    values: np.ndarray


@dataclass(frozen=True)
class Sync(Message):
    KIND, OP = CONTROL, "sync"


@dataclass(frozen=True)
class GetState(Message):
    KIND, OP = CONTROL, "get_state"


@dataclass(frozen=True)
class SetState(Message):
    KIND, OP = CONTROL, "set_state"
    state: bytes


@dataclass(frozen=True)
class Terminate(Message):
    KIND, OP = CONTROL, "terminate"
    final: bool


@dataclass(frozen=True)
class Reply(Message):
    """The answer to command ``op``; ``details`` are the JSON object's other keys."""

    KIND = REPLY
    op: str
    details: dict[str, Json] = field(default_factory=dict)
    blob: bytes = b""

    def encode(self) -> bytes:
        return frame(REPLY, {"op": self.op, **self.details}, self.blob)

    @classmethod
    def from_parts(cls, body: dict, blob: bytes) -> Reply:
        details = dict(body)
        return cls(from_json(details.pop("op", None), str, "Reply.op"), details, blob)


@dataclass(frozen=True)
class Fault(Message):
    KIND = FAULT
    op: str  # where it failed: "step", "nan" (a non-finite output, named in error), or a command's op
    k: int
    error: str


@dataclass(frozen=True)
class Events(Message):
    KIND, OP = EVENT, "events"
    k: int
    events: list[tuple[str, dict[str, Json]]]


@dataclass(frozen=True)
class Beat(Bare):
    KIND = BEAT


@dataclass(frozen=True)
class Quit(Bare):
    KIND = QUIT


COMMANDS_SENT = (Horizon, Instantiate, Wire, Initialize, Sync, Start, Rewire, GetState, SetState, Terminate)
REPORTS = (Reply, Fault, Events, Beat)
MESSAGES = (*COMMANDS_SENT, *REPORTS, Quit)

decode_command = OneOf("command", COMMANDS_SENT)  # what comes on a component's COMMANDS key
decode_report = OneOf("report", REPORTS)  # what comes on a component's REPLIES key
