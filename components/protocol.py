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
| ``CTL`` | ``ctl`` | CLI -> orchestrator | queryable: status, stop, swap (JSON) |
| ``JOIN`` | ``join/<name>`` | joiner -> orchestrator | queryable: which generation to serve (JSON) |

Messages: a first byte says the kind; ``C``, ``R``, ``E`` and ``V`` then hold a JSON object
(length-prefixed, uint32 little-endian) and a blob (the rest); the JSON object's ``op`` names
the command, or for ``R`` and ``E`` the command answered. Times in integer ns, values float64.

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
or :func:`decode_command` / :func:`decode_report` for whatever comes on a topic); a decoder
raises :class:`Malformed` for anything but a well-formed message of its type, whose fields then
have their declared types.
"""

from __future__ import annotations

import dataclasses
import json
import struct
import typing
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from components.schedule import Route

ROOT = "zenorbit"
ORCHESTRATOR = "orchestrator"  # the orchestrator's liveliness name


class Malformed(ValueError):
    """A payload (or key) that is not a well-formed message of the kind expected: dropped, never fatal."""


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
                if name not in fields and wildcard is None:
                    raise TypeError(f"key of {self.template!r}: no value for {name!r} (given: {', '.join(fields)})")
                chunk = str(fields[name]) if name in fields else wildcard
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
_JSON_LENGTH = struct.Struct("<I")

Json = Any  # a field holding any JSON value, taken as it comes


# ----------------------------------------------------------------------------- the codec


class Message:
    """A control message: a frozen dataclass whose fields, in order, are its JSON object after
    ``op`` (see the module's table); a field typed ``bytes`` or ``np.ndarray`` (float64) is the
    blob. ``KIND`` is its first byte, ``OP`` its fixed ``op`` (None: an ``op`` field instead)."""

    KIND: ClassVar[bytes]
    OP: ClassVar[str | None] = None

    def encode(self) -> bytes:
        body, blob = {} if self.OP is None else {"op": self.OP}, b""
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name != _blob_field(type(self)):
                body[f.name] = _to_json(value)
            elif _hints(type(self))[f.name] is bytes:
                blob = bytes(value)
            else:
                blob = np.ascontiguousarray(value, dtype=np.float64).tobytes()
        return _frame(self.KIND, body, blob)

    @classmethod
    def decode(cls, payload: bytes):
        """The message in ``payload``; Malformed unless it is exactly one of this type."""
        body, blob = _unframe(payload, cls.KIND, cls.__name__)
        return cls._from_parts(body, blob)

    @classmethod
    def _from_parts(cls, body: dict, blob: bytes):
        name = cls.__name__
        if cls.OP is not None and body.get("op") != cls.OP:
            raise Malformed(f"{name}: expected op {cls.OP!r}, got {body.get('op')!r:.40}")
        hints, blob_field, values = _hints(cls), _blob_field(cls), {}
        for f in dataclasses.fields(cls):
            if f.name == blob_field:
                values[f.name] = _from_blob(blob, hints[f.name], f"{name}.{f.name}")
            elif f.name in body:
                values[f.name] = _from_json(body[f.name], hints[f.name], f"{name}.{f.name}")
            else:
                raise Malformed(f"{name}: expected a field {f.name!r}, got only {', '.join(map(repr, body))}")
        if blob and blob_field is None:
            raise Malformed(f"{name}: expected no blob, got {len(blob)} bytes")
        message = cls(**values)
        message._check()
        return message

    def _check(self) -> None:
        """Malformed unless the fields agree with each other (a decoded message's types are checked already)."""


def _frame(kind: bytes, body: dict, blob: bytes) -> bytes:
    text = json.dumps(body).encode()
    return kind + _JSON_LENGTH.pack(len(text)) + text + blob


def _unframe(payload: bytes, kind: bytes, name: str) -> tuple[dict, bytes]:
    """(JSON object, blob) of a message of ``kind``."""
    if payload[:1] != kind:
        raise Malformed(f"{name}: expected first byte {kind!r}, got {bytes(payload[:1])!r}")
    if len(payload) < 1 + _JSON_LENGTH.size:
        raise Malformed(f"{name}: expected at least {1 + _JSON_LENGTH.size} bytes, got {len(payload)}")
    (n,) = _JSON_LENGTH.unpack_from(payload, 1)
    start = 1 + _JSON_LENGTH.size
    if start + n > len(payload):
        raise Malformed(f"{name}: announces {n} bytes of JSON, got {len(payload) - start} bytes after the header")
    try:
        body = json.loads(payload[start : start + n])
    except (ValueError, RecursionError) as e:  # JSONDecodeError, UnicodeDecodeError; nesting too deep
        raise Malformed(f"{name}: expected a JSON object, got text that is not JSON ({e})") from None
    if not isinstance(body, dict):
        raise Malformed(f"{name}: expected a JSON object, got {body!r:.60}")
    return body, bytes(payload[start + n :])


def _hints(cls) -> dict:
    hints = cls.__dict__.get("_resolved_hints")
    if hints is None:
        hints = typing.get_type_hints(cls)
        cls._resolved_hints = hints
    return hints


def _blob_field(cls) -> str | None:
    hints = _hints(cls)
    blobs = [f.name for f in dataclasses.fields(cls) if hints[f.name] in (bytes, np.ndarray)]
    return blobs[0] if blobs else None


def _to_json(value):
    if isinstance(value, Route):
        return value.to_json()
    if isinstance(value, (list, tuple)):
        return [_to_json(v) for v in value]
    if isinstance(value, dict):
        return {k: _to_json(v) for k, v in value.items()}
    return value


_SCALARS = {int: "an integer in int64's range", float: "a number", str: "a string", bool: "true or false"}


def _from_json(value, hint, where: str):
    """``value`` as ``hint`` says: int, float, str, bool, Json, Route, list[X], dict[str, X] or
    tuple[X, Y, ...] (an array of that length); Malformed otherwise."""
    if hint is Json:
        return value
    if hint in _SCALARS:
        if hint is float and isinstance(value, int) and not isinstance(value, bool) and abs(value) < 2**1023:
            return float(value)
        if not isinstance(value, hint) or (hint is int and (isinstance(value, bool) or not -(2**63) <= value < 2**63)):
            raise Malformed(f"{where}: expected {_SCALARS[hint]}, got {value!r:.40}")
        return value
    if hint is Route:
        return _route(_from_json(value, dict[str, Json], where), where)
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is list:
        if not isinstance(value, list):
            raise Malformed(f"{where}: expected an array, got {value!r:.40}")
        return [_from_json(v, args[0], f"{where}[{i}]") for i, v in enumerate(value)]
    if origin is tuple:
        if not isinstance(value, list) or len(value) != len(args):
            raise Malformed(f"{where}: expected an array of {len(args)}, got {value!r:.40}")
        return tuple(_from_json(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
    if origin is dict:
        if not isinstance(value, dict):
            raise Malformed(f"{where}: expected an object, got {value!r:.40}")
        return {k: _from_json(v, args[1], f"{where}[{k!r:.20}]") for k, v in value.items()}
    raise TypeError(f"{where}: no JSON form for {hint!r}")  # a declaration this codec cannot carry


def _route(data: dict, where: str) -> Route:
    keys = ("source", "src", "dst", "ratio", "ahead")
    if sorted(data) != sorted(keys):
        raise Malformed(f"{where}: expected a route of {', '.join(keys)}, got {', '.join(data)}")
    src, dst = (_from_json(data[k], list[int], f"{where}.{k}") for k in ("src", "dst"))
    ratio, ahead = (_from_json(data[k], int, f"{where}.{k}") for k in ("ratio", "ahead"))
    if len(src) != len(dst) or min(src + dst, default=0) < 0 or ratio < 1 or ahead not in (0, 1):
        raise Malformed(
            f"{where}: expected src and dst of one length, indices >= 0, ratio >= 1 and ahead 0 or 1, "
            f"got {len(src)} and {len(dst)} indices, ratio {ratio}, ahead {ahead}"
        )
    return Route(
        _from_json(data["source"], str, f"{where}.source"),
        np.asarray(src, dtype=np.int64),
        np.asarray(dst, dtype=np.int64),
        ratio,
        ahead,
    )


def _from_blob(blob: bytes, hint, where: str):
    if hint is bytes:
        return blob
    if len(blob) % 8:
        raise Malformed(f"{where}: expected float64 values (a multiple of 8 bytes), got {len(blob)} bytes")
    return np.frombuffer(blob, dtype=np.float64)


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

    def _check(self) -> None:
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
        return _frame(REPLY, {"op": self.op, **self.details}, self.blob)

    @classmethod
    def _from_parts(cls, body: dict, blob: bytes) -> Reply:
        details = dict(body)
        return cls(_from_json(details.pop("op", None), str, "Reply.op"), details, blob)


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
class _Bare(Message):
    """A message of one byte."""

    def encode(self) -> bytes:
        return self.KIND

    @classmethod
    def decode(cls, payload: bytes):
        if payload != cls.KIND:
            raise Malformed(
                f"{cls.__name__}: expected the one byte {cls.KIND!r}, got {bytes(payload[:8])!r} ({len(payload)} bytes)"
            )
        return cls()


@dataclass(frozen=True)
class Beat(_Bare):
    KIND = BEAT


@dataclass(frozen=True)
class Quit(_Bare):
    KIND = QUIT


COMMANDS_SENT = (Horizon, Instantiate, Wire, Initialize, Sync, Start, Rewire, GetState, SetState, Terminate)
REPORTS = (Reply, Fault, Events, Beat)
MESSAGES = (*COMMANDS_SENT, *REPORTS, Quit)

_BY_OP = {m.OP: m for m in COMMANDS_SENT if m.OP is not None}
_REPORT_BY_KIND = {m.KIND: m for m in REPORTS}


def decode_command(payload: bytes) -> Message:
    """What came on a component's COMMANDS key: a Horizon or a command; Malformed otherwise."""
    if payload[:1] == HORIZON:
        return Horizon.decode(payload)
    body, blob = _unframe(payload, CONTROL, "command")
    op = body.get("op")
    kind = _BY_OP.get(op) if isinstance(op, str) else None
    if kind is None:
        raise Malformed(f"command: expected op one of {', '.join(_BY_OP)}, got {body.get('op')!r:.40}")
    return kind._from_parts(body, blob)


def decode_report(payload: bytes) -> Message:
    """What came on a component's REPLIES key: a Reply, Fault, Events or Beat; Malformed otherwise."""
    kind = _REPORT_BY_KIND.get(bytes(payload[:1]))
    if kind is None:
        raise Malformed(f"report: expected first byte one of {b''.join(_REPORT_BY_KIND)!r}, got {bytes(payload[:1])!r}")
    return kind.decode(payload)
