"""The codec of the bus's control messages (:mod:`components.protocol`, :mod:`components.queries`):
a message is a frozen dataclass, declared once; its fields' types say how it is framed and what a
decoder accepts.

A framed message is a first byte (its kind), a JSON object (length-prefixed, uint32
little-endian) and a blob (the rest). The JSON object's ``op`` names the message among those of
its kind. A field typed ``bytes`` or ``np.ndarray`` (float64) is the blob; the others are JSON:
int, float, str, bool, ``X | None``, :data:`Json` (any value), a Route, a frozen dataclass (an
object of its fields), list[X], dict[str, X] or tuple[X, Y, ...] (an array of that length).
"""

from __future__ import annotations

import dataclasses
import json
import struct
import types
import typing
from typing import Any, ClassVar

import numpy as np

from components.schedule import Route


class Malformed(ValueError):
    """A payload (or key) that is not a well-formed message of the kind expected: dropped, never fatal."""


Json = Any  # a field holding any JSON value, taken as it comes

_JSON_LENGTH = struct.Struct("<I")


class Message:
    """A control message: a frozen dataclass whose fields, in order, are its JSON object after
    ``op``; a field typed ``bytes`` or ``np.ndarray`` (float64) is the blob. ``KIND`` is its
    first byte, ``OP`` its fixed ``op`` (None: an ``op`` field instead)."""

    KIND: ClassVar[bytes]
    OP: ClassVar[str | None] = None
    __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]  # each message is a dataclass

    def encode(self) -> bytes:
        body, blob = {} if self.OP is None else {"op": self.OP}, b""
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name != blob_field(type(self)):
                body[f.name] = to_json(value)
            elif hints(type(self))[f.name] is bytes:
                blob = bytes(value)
            else:
                blob = np.ascontiguousarray(value, dtype=np.float64).tobytes()
        return frame(self.KIND, body, blob)

    @classmethod
    def decode(cls, payload: bytes):
        """The message in ``payload``; Malformed unless it is exactly one of this type."""
        body, blob = unframe(payload, cls.KIND, cls.__name__)
        return cls.from_parts(body, blob)

    @classmethod
    def from_parts(cls, body: dict, blob: bytes):
        """The message of an unframed JSON object and blob; Malformed unless they are one of this type."""
        name = cls.__name__
        if cls.OP is not None and body.get("op") != cls.OP:
            raise Malformed(f"{name}: expected op {cls.OP!r}, got {body.get('op')!r:.40}")
        declared, blob_name, values = hints(cls), blob_field(cls), {}
        for f in dataclasses.fields(cls):
            if f.name == blob_name:
                values[f.name] = _from_blob(blob, declared[f.name], f"{name}.{f.name}")
            elif f.name in body:
                values[f.name] = from_json(body[f.name], declared[f.name], f"{name}.{f.name}")
            else:
                raise Malformed(f"{name}: expected a field {f.name!r}, got only {', '.join(map(repr, body))}")
        if blob and blob_name is None:
            raise Malformed(f"{name}: expected no blob, got {len(blob)} bytes")
        message = cls(**values)
        message.check()
        return message

    def check(self) -> None:
        """Malformed unless the fields agree with each other (a decoded message's types are checked already)."""


@dataclasses.dataclass(frozen=True)
class Bare(Message):
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


class OneOf:
    """The decoder of whatever comes on one key: one of ``messages``, told apart by their first
    byte and, among those of one kind, by their ``op``; Malformed for anything else."""

    def __init__(self, name: str, messages: tuple[type[Message], ...]):
        self.name, self.messages = name, messages
        self.by_kind: dict[bytes, dict[str | None, type[Message]]] = {}
        for message in messages:
            self.by_kind.setdefault(message.KIND, {})[message.OP] = message

    def __call__(self, payload: bytes) -> Message:
        kind = bytes(payload[:1])
        ops = self.by_kind.get(kind)
        if ops is None:
            raise Malformed(f"{self.name}: expected first byte one of {b''.join(self.by_kind)!r}, got {kind!r}")
        if len(ops) == 1:
            return next(iter(ops.values())).decode(payload)
        body, blob = unframe(payload, kind, self.name)
        op = body.get("op")
        message = ops.get(op) if isinstance(op, str) else None
        if message is None:
            raise Malformed(f"{self.name}: expected op one of {', '.join(map(str, ops))}, got {body.get('op')!r:.40}")
        return message.from_parts(body, blob)


def frame(kind: bytes, body: dict, blob: bytes) -> bytes:
    text = json.dumps(body).encode()
    return kind + _JSON_LENGTH.pack(len(text)) + text + blob


def unframe(payload: bytes, kind: bytes, name: str) -> tuple[dict, bytes]:
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


def hints(cls) -> dict:
    """The field types of a message class, resolved once."""
    found = cls.__dict__.get("_resolved_hints")
    if found is None:
        found = typing.get_type_hints(cls)
        cls._resolved_hints = found
    return found


def blob_field(cls) -> str | None:
    declared = hints(cls)
    blobs = [f.name for f in dataclasses.fields(cls) if declared[f.name] in (bytes, np.ndarray)]
    return blobs[0] if blobs else None


def to_json(value):
    if isinstance(value, Route):
        return value.to_json()
    if dataclasses.is_dataclass(value):
        return {f.name: to_json(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, (list, tuple)):
        return [to_json(v) for v in value]
    if isinstance(value, dict):
        return {k: to_json(v) for k, v in value.items()}
    return value


_SCALARS = {int: "an integer in int64's range", float: "a number", str: "a string", bool: "true or false"}


def from_json(value, hint, where: str):
    """``value`` as ``hint`` says (see the module's list of types); Malformed otherwise."""
    if hint is Json:
        return value
    if hint in _SCALARS:
        if hint is float and isinstance(value, int) and not isinstance(value, bool) and abs(value) < 2**1023:
            return float(value)
        if not isinstance(value, hint) or (hint is int and (isinstance(value, bool) or not -(2**63) <= value < 2**63)):
            raise Malformed(f"{where}: expected {_SCALARS[hint]}, got {value!r:.40}")
        return value
    if hint is Route:
        return _route(from_json(value, dict[str, Json], where), where)
    if dataclasses.is_dataclass(hint):
        return _record(from_json(value, dict[str, Json], where), hint, where)
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType) and len(args) == 2 and type(None) in args:
        return None if value is None else from_json(value, next(a for a in args if a is not type(None)), where)
    if origin is list:
        if not isinstance(value, list):
            raise Malformed(f"{where}: expected an array, got {value!r:.40}")
        return [from_json(v, args[0], f"{where}[{i}]") for i, v in enumerate(value)]
    if origin is tuple:
        if not isinstance(value, list) or len(value) != len(args):
            raise Malformed(f"{where}: expected an array of {len(args)}, got {value!r:.40}")
        return tuple(from_json(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
    if origin is dict:
        if not isinstance(value, dict):
            raise Malformed(f"{where}: expected an object, got {value!r:.40}")
        return {k: from_json(v, args[1], f"{where}[{k!r:.20}]") for k, v in value.items()}
    raise TypeError(f"{where}: no JSON form for {hint!r}")  # a declaration this codec cannot carry


def _record(data: dict, cls, where: str):
    """A frozen dataclass from an object holding exactly its fields."""
    names = [f.name for f in dataclasses.fields(cls)]
    if sorted(data) != sorted(names):
        raise Malformed(f"{where}: expected an object of {', '.join(names)}, got {', '.join(data):.80}")
    declared = typing.get_type_hints(cls)
    return cls(**{n: from_json(data[n], declared[n], f"{where}.{n}") for n in names})


def _route(data: dict, where: str) -> Route:
    keys = ("source", "src", "dst", "ratio", "ahead")
    if sorted(data) != sorted(keys):
        raise Malformed(f"{where}: expected a route of {', '.join(keys)}, got {', '.join(data)}")
    src, dst = (from_json(data[k], list[int], f"{where}.{k}") for k in ("src", "dst"))
    ratio, ahead = (from_json(data[k], int, f"{where}.{k}") for k in ("ratio", "ahead"))
    if len(src) != len(dst) or min(src + dst, default=0) < 0 or ratio < 1 or ahead not in (0, 1):
        raise Malformed(
            f"{where}: expected src and dst of one length, indices >= 0, ratio >= 1 and ahead 0 or 1, "
            f"got {len(src)} and {len(dst)} indices, ratio {ratio}, ahead {ahead}"
        )
    return Route(
        from_json(data["source"], str, f"{where}.source"),
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
