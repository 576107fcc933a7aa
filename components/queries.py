"""The queries on a run's bus, declared as the rest of the protocol (:mod:`components.protocol`)
and framed by the same codec: the CLI's requests on ``CTL`` (``orchestrator ps``, ``stop``,
``swap``) and a joining component's on ``JOIN`` (``orchestrator join``), each with the run's
answers. A request's first byte is ``A``, an answer's ``N``; the JSON object's ``op`` names it.

| message | op | topic | fields |
|---|---|---|---|
| ``Status`` | status | CTL, CLI -> run | (none) |
| ``Stop`` | stop | CTL, CLI -> run | (none) |
| ``Swap`` | swap | CTL, CLI -> run | ``component``; ``type`` (null: its own); ``set`` (``KEY=VALUE`` of its parameters) |
| ``RunStatus`` | status | CTL, run -> CLI | ``run_id``, ``name``, ``step``, ``steps``, ``time`` (s); ``components`` (name -> type, generation, shadow_of) |
| ``Stopping`` | stopping | CTL, run -> CLI | (none): the run stops at its next step boundary |
| ``Swapped`` | swapped | CTL, run -> CLI | ``step`` (where), ``generation`` (the new one's) |
| ``Refused`` | refused | CTL, run -> CLI | ``error``; ``usage``: the request's fault (else a replacement failed to start) |
| ``Join`` | join | JOIN, joiner -> run | ``address``, ``hostname``, ``pid``, ``zid`` (its Zenoh session) |
| ``Granted`` | granted | JOIN, run -> joiner | ``generation`` to serve; ``orchestrator`` (its Zenoh id) |
| ``Wait`` | wait | JOIN, run -> joiner | (none): between generations (a restart under way), ask again |
| ``JoinRefused`` | join_refused | JOIN, run -> joiner | ``error``: not a component that joins, or one joined already |
| ``Over`` | over | JOIN, run -> joiner | (none): the run has ended |
"""

from __future__ import annotations

from dataclasses import dataclass

from components.message_codec import Message, OneOf

REQUEST = b"A"  # CLI or joiner -> run
ANSWER = b"N"  # run -> CLI or joiner


@dataclass(frozen=True)
class Status(Message):
    KIND, OP = REQUEST, "status"


@dataclass(frozen=True)
class Stop(Message):
    KIND, OP = REQUEST, "stop"


@dataclass(frozen=True)
class Swap(Message):
    KIND, OP = REQUEST, "swap"
    component: str
    type: str | None
    set: list[str]


@dataclass(frozen=True)
class Running:
    """A live component, as ``orchestrator ps`` shows it."""

    type: str
    generation: int
    shadow_of: str | None


@dataclass(frozen=True)
class RunStatus(Message):
    KIND, OP = ANSWER, "status"
    run_id: str
    name: str
    step: int
    steps: int
    time: float
    components: dict[str, Running]


@dataclass(frozen=True)
class Stopping(Message):
    KIND, OP = ANSWER, "stopping"


@dataclass(frozen=True)
class Swapped(Message):
    KIND, OP = ANSWER, "swapped"
    step: int
    generation: int


@dataclass(frozen=True)
class Refused(Message):
    KIND, OP = ANSWER, "refused"
    error: str
    usage: bool


@dataclass(frozen=True)
class Join(Message):
    KIND, OP = REQUEST, "join"
    address: str
    hostname: str
    pid: int
    zid: str


@dataclass(frozen=True)
class Granted(Message):
    KIND, OP = ANSWER, "granted"
    generation: int
    orchestrator: str


@dataclass(frozen=True)
class Wait(Message):
    KIND, OP = ANSWER, "wait"


@dataclass(frozen=True)
class JoinRefused(Message):
    KIND, OP = ANSWER, "join_refused"
    error: str


@dataclass(frozen=True)
class Over(Message):
    KIND, OP = ANSWER, "over"


CONTROL_REQUESTS = (Status, Stop, Swap)
CONTROL_ANSWERS = (RunStatus, Stopping, Swapped, Refused)
JOIN_ANSWERS = (Granted, Wait, JoinRefused, Over)
MESSAGES = (*CONTROL_REQUESTS, *CONTROL_ANSWERS, Join, *JOIN_ANSWERS)

decode_control_request = OneOf("control request", CONTROL_REQUESTS)  # what comes on CTL
decode_control_answer = OneOf("control answer", CONTROL_ANSWERS)
decode_join_answer = OneOf("join answer", JOIN_ANSWERS)
