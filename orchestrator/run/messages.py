"""What reaches the orchestrator's inbox: the subscriptions that put it there as (kind, key,
payload), and :func:`decode`, a pure function from that to a typed message, or
:class:`components.bus.Malformed`. Whether the message is from a live member is for the engine to
check; here only its form is."""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np

from components import bus, protocol

# what protocol.decode_report returns (one of protocol.REPORTS), which its signature does not say
ReportMessage = protocol.Reply | protocol.Fault | protocol.Events | protocol.Beat

# inbox kinds: what the subscription callbacks enqueue, with the key and the payload
OUTPUTS = "o"  # a batch of step outputs (payload: bytes)
REPLY = "r"  # a reply or a fault (payload: bytes)
LIVELINESS = "l"  # a liveliness token came (payload: True) or went (False)
LINK = "t"  # the link to a session closed (key: its Zenoh id): lease expired, or the session ended
CONTROL = "ctl"  # a query from the CLI (key: the query; not decoded here)


@dataclass(slots=True)
class Outputs:
    name: str
    generation: int
    tags: np.ndarray  # (n,), increasing, >= 1
    timings: np.ndarray  # (n, 2): compute and idle seconds of each step
    outputs: np.ndarray  # (n, size)


@dataclass(slots=True)
class Report:
    """What a member said on its REPLIES key: a protocol.Reply, Fault, Events or Beat."""

    name: str
    generation: int
    message: ReportMessage


@dataclass(slots=True)
class Liveliness:
    name: str
    generation: int
    alive: bool


@dataclass(slots=True)
class LinkLost:
    zid: str


def decode(kind: str, key: str, payload) -> Outputs | Report | Liveliness | LinkLost | None:
    """The message of an inbox entry; None for a liveliness token that is not a process's."""
    if kind == OUTPUTS:
        generation, tags, timings, outputs = bus.decode_batch(payload)
        if tags[0] < 1:
            raise bus.Malformed(f"tag {tags[0]}: the outputs of a step are tagged 1 or later")
        return Outputs(bus.batch_source(key), generation, tags, timings, outputs)
    if kind == REPLY:
        return Report(*bus.reply_source(key), cast(ReportMessage, protocol.decode_report(payload)))
    if kind == LIVELINESS:
        source = bus.alive_source(key)
        return None if source is None else Liveliness(*source, payload)
    if kind == LINK:
        return LinkLost(key)
    raise ValueError(f"no inbox kind {kind!r}")


def subscribe(session, run_id: str, put) -> list:
    """The orchestrator's subscriptions on ``session``, each callback only enqueuing with ``put``,
    and its liveliness token; they last as long as the list is held."""
    import zenoh

    put_kind = zenoh.SampleKind.PUT

    def outputs(sample) -> None:
        put((OUTPUTS, str(sample.key_expr), sample.payload.to_bytes()))

    def reply(sample) -> None:
        put((REPLY, str(sample.key_expr), sample.payload.to_bytes()))

    def liveliness(sample) -> None:
        put((LIVELINESS, str(sample.key_expr), sample.kind == put_kind))

    def control(query) -> None:
        put((CONTROL, query, None))

    def link(event) -> None:  # the one sure sign of a cut link: a token may stay known through another peer
        if event.kind != put_kind:
            put((LINK, str(event.transport.zid), None))

    return [
        session.declare_subscriber(bus.batch_pattern(run_id), outputs),
        session.declare_subscriber(bus.reply_pattern(run_id), reply),
        session.liveliness().declare_subscriber(bus.alive_pattern(run_id), liveliness),
        session.declare_queryable(bus.control_key(run_id), control),
        session.liveliness().declare_token(bus.orchestrator_alive_key(run_id)),
        session.info.declare_transport_events_listener(link),
    ]
