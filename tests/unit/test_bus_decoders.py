"""Every decoder of the wire protocol, fuzzed: a well-formed message decodes to what was encoded,
and anything else (random bytes, truncations, bit flips, wrong lengths, fields of the wrong type)
raises Malformed and nothing else, so whoever can reach the bus cannot crash a run. The control
messages and the queries are enumerated from components.protocol.MESSAGES and
components.queries.MESSAGES, so a new one is fuzzed too."""

import json
import struct
import zlib

import numpy as np
import pytest

from components import bus, protocol, queries
from components.schedule import Route

RNG = np.random.default_rng(20261124)


def _valid_messages() -> dict[str, bytes]:
    outputs = np.arange(12.0).reshape(3, 4)
    return {
        "output": bus.encode_output(2, 7, outputs[0]),
        "batch": bus.encode_batch(2, np.array([5, 6, 7]), np.ones((3, 2)), outputs),
        "sync": bus.encode_sync(3),
    }


DECODERS = {
    "output": bus.decode_output,
    "batch": bus.decode_batch,
    "sync": bus.decode_sync,
    "state": bus.decode_state,
}


def test_well_formed_messages_decode_to_what_was_encoded():
    m = _valid_messages()
    generation, tag, vector = bus.decode_output(m["output"])
    assert (generation, tag, vector.tolist()) == (2, 7, [0.0, 1.0, 2.0, 3.0])
    generation, tags, _timings, outputs = bus.decode_batch(m["batch"])
    assert generation == 2 and tags.tolist() == [5, 6, 7] and outputs[2].tolist() == [8.0, 9.0, 10.0, 11.0]
    assert bus.decode_sync(m["sync"]) == 3


def _mutations(payload: bytes):
    """Truncations at every length, single bit flips, random tails and pure noise."""
    for n in range(len(payload)):
        yield payload[:n]
    for _ in range(300):
        flipped = bytearray(payload)
        i = int(RNG.integers(len(flipped)))
        flipped[i] ^= 1 << int(RNG.integers(8))
        yield bytes(flipped)
    for _ in range(100):
        yield payload + RNG.bytes(int(RNG.integers(1, 40)))
        yield RNG.bytes(int(RNG.integers(0, 200)))
    yield b"\x00\x01\x02"  # the 3 bytes that used to end a run


@pytest.mark.parametrize("kind", list(DECODERS))
def test_every_decoder_raises_only_malformed_on_garbage(kind):
    payload = _valid_messages().get(kind) or bus.encode_state({"q": np.arange(5.0)})
    decode = DECODERS[kind]
    rejected = 0
    for mutated in _mutations(payload):
        try:
            decode(mutated)
        except bus.Malformed:
            rejected += 1
        # any other exception fails the test: it would have reached the run
    assert rejected > 100, f"{kind}: only {rejected} mutations rejected; the decoder checks too little"


@pytest.mark.parametrize(
    "payload, message",
    [
        (bus.encode_batch(0, np.array([3, 2]), np.zeros((2, 2)), np.zeros((2, 1))), "not increasing"),
        (bus.encode_batch(0, np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros((0, 3))), "does not hold 0 steps"),
        (bus.encode_batch(0, np.array([1]), np.zeros((1, 2)), np.zeros((1, 3)))[:-8], "does not hold"),
        (bus.encode_output(0, 1, np.zeros(2))[:-3], "whole number of float64"),
    ],
)
def test_malformed_says_what_is_wrong(payload, message):
    with pytest.raises(bus.Malformed, match=message):
        (bus.decode_batch if payload[:1] == bus.BATCH else bus.decode_output)(payload)


# ------------------------------------------------------------------ the control messages (components.protocol)


def _route(source: str, src: list[int], dst: list[int], ratio: int, ahead: int) -> Route:
    return Route(source, np.array(src, dtype=np.int64), np.array(dst, dtype=np.int64), ratio, ahead)


EXAMPLES = {  # each declared message with values that are not defaults
    protocol.Horizon: protocol.Horizon(2**40 + 3),
    protocol.Instantiate: protocol.Instantiate(
        "dynamics.pinocchio",
        {"mass": 12.5, "urdf": "arm.urdf", "gains": [1, 2.5], "nested": {"a": None}},
        {"epoch": "2022-09-18T12:00:00Z", "config_dir": "/configs", "packages": {"arm": "/arm"}, "frames": None},
    ),
    protocol.Wire: protocol.Wire(
        generation=3,
        step_ns=1_000_000,
        ratio=4,
        k=120,
        consumers=["controller", "viewer"],
        batch_consumers=["logger"],
        routes=[_route("orbit", [0, 1, 2], [5, 6, 7], 2, 1), _route("sensor", [], [], 1, 0)],
        sources={"orbit": 3, "sensor": 0},
        faults=[(40, "crash", 0.0), (80, "delay", 1.5)],
        frame_routes=[("camera", "rgb", "image", 10, 1)],
        frame_consumers={"rgb": ["viewer"]},
    ),
    protocol.Initialize: protocol.Initialize(
        7_000_000_000, {"q": 6_000_000_000, "qd": 0}, np.array([1.5, -2.0, 1e-300])
    ),
    protocol.Sync: protocol.Sync(),
    protocol.Start: protocol.Start(
        [("orbit", 8, 2), ("orbit", 9, 2), ("sensor", 8, 1)], 64, np.array([1.0, 2.0, 3.0, 4.0, -5.0])
    ),
    protocol.Rewire: protocol.Rewire(
        [("dynamics", 12, 3)], [_route("dynamics", [2, 0], [1, 3], 1, 0)], {"dynamics": 2}, np.array([0.5, 0.25, 0.125])
    ),
    protocol.GetState: protocol.GetState(),
    protocol.SetState: protocol.SetState(bus.encode_state({"x": np.arange(4.0), "k": np.int64(3)})),
    protocol.Terminate: protocol.Terminate(final=True),
    protocol.Reply: protocol.Reply("instantiate", {"inputs": 13, "outputs": 21, "pid": 4242}, b"\x00\x01\xff"),
    protocol.Fault: protocol.Fault("step", 17, "ValueError: the arm left its workspace"),
    protocol.Events: protocol.Events(
        33, [("capture_closed", {"time": 12.5, "reason": "within tolerance"}), ("capture_retreat", {})]
    ),
    protocol.Beat: protocol.Beat(),
    protocol.Quit: protocol.Quit(),
    queries.Status: queries.Status(),
    queries.Stop: queries.Stop(),
    queries.Swap: queries.Swap("controller", "controller.pd", ["kp=40", "gains=[1, 2]"]),
    queries.RunStatus: queries.RunStatus(
        "demo-1a2b3c4d",
        "demo",
        1200,
        15000,
        1.2,
        {"arm": queries.Running("dynamics.pinocchio", 2, None), "twin": queries.Running("dynamics.dart", 0, "arm")},
    ),
    queries.Stopping: queries.Stopping(),
    queries.Swapped: queries.Swapped(9000, 1),
    queries.Refused: queries.Refused("no component 'x' (components: arm)", usage=True),
    queries.Join: queries.Join("192.0.2.2", "flight", 4242, "a1b2c3"),
    queries.Granted: queries.Granted(3, "f00d"),
    queries.Wait: queries.Wait(),
    queries.JoinRefused: queries.JoinRefused("component 'arm' has joined already"),
    queries.Over: queries.Over(),
}
MESSAGES = (*protocol.MESSAGES, *queries.MESSAGES)

# what decodes whatever comes on each message's key
DISPATCHERS = {
    **dict.fromkeys(protocol.COMMANDS_SENT, protocol.decode_command),
    **dict.fromkeys(protocol.REPORTS, protocol.decode_report),
    **dict.fromkeys(queries.CONTROL_REQUESTS, queries.decode_control_request),
    **dict.fromkeys(queries.CONTROL_ANSWERS, queries.decode_control_answer),
    **dict.fromkeys(queries.JOIN_ANSWERS, queries.decode_join_answer),
}


def _same(a, b) -> bool:
    """Equal, arrays and Routes compared by value and type."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return type(a) is type(b) and a.dtype == b.dtype and np.array_equal(a, b)
    if type(a) is not type(b):
        return False
    if isinstance(a, (Route, protocol.Message, queries.Running)):
        return all(_same(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return a == b


def test_every_declared_message_has_an_example():
    assert set(EXAMPLES) == set(MESSAGES), "give a new message an example here: it is fuzzed then"


@pytest.mark.parametrize("kind", MESSAGES, ids=lambda kind: kind.__name__)
def test_a_message_decodes_to_what_was_encoded(kind):
    message = EXAMPLES[kind]
    payload = message.encode()
    for decode in (kind.decode, DISPATCHERS.get(kind, kind.decode)):
        decoded = decode(payload)
        assert _same(decoded, message), f"{kind.__name__}: {decoded!r} != {message!r}"
        assert decoded.encode() == payload


def test_the_wire_bytes_are_those_of_the_json_messages_before_them():
    """The bytes of the dict-built messages the protocol replaced: a component of either version
    reads the other's."""

    def framed(kind: bytes, body: dict, blob: bytes = b"") -> bytes:
        text = json.dumps(body).encode()
        return kind + struct.pack("<I", len(text)) + text + blob

    wire = EXAMPLES[protocol.Wire]
    assert wire.encode() == framed(
        b"C",
        {
            "op": "wire",
            "generation": 3,
            "step_ns": 1_000_000,
            "ratio": 4,
            "k": 120,
            "consumers": ["controller", "viewer"],
            "batch_consumers": ["logger"],
            "routes": [r.to_json() for r in wire.routes],
            "sources": {"orbit": 3, "sensor": 0},
            "faults": [[40, "crash", 0.0], [80, "delay", 1.5]],
            "frame_routes": [["camera", "rgb", "image", 10, 1]],
            "frame_consumers": {"rgb": ["viewer"]},
        },
    )
    assert EXAMPLES[protocol.Start].encode() == framed(
        b"C",
        {"op": "start", "held": [["orbit", 8, 2], ["orbit", 9, 2], ["sensor", 8, 1]], "horizon": 64},
        np.array([1.0, 2.0, 3.0, 4.0, -5.0]).tobytes(),
    )
    assert protocol.Reply("wire").encode() == framed(b"R", {"op": "wire"})
    assert EXAMPLES[protocol.Fault].encode() == framed(
        b"E", {"op": "step", "k": 17, "error": "ValueError: the arm left its workspace"}
    )
    assert protocol.Horizon(40).encode() == b"H" + struct.pack("<q", 40)
    assert (protocol.Beat().encode(), protocol.Quit().encode()) == (b"K", b"Q")


def test_topics_spell_the_keys_and_cover_them_for_access_control():
    assert protocol.COMMANDS.key("r-1", name="arm", generation=2) == "zenorbit/r-1/i/arm/c/2"
    assert protocol.REPLIES.pattern("r-1") == "zenorbit/r-1/c/*/*/out"
    assert protocol.COMMANDS.covering("r-1") == "zenorbit/r-1/i/*/c/**"
    assert protocol.JOIN.covering("r-1") == "zenorbit/r-1/join/**"
    assert protocol.CTL.covering("r-1") == "zenorbit/r-1/ctl"
    assert protocol.OUTPUTS.key("r-1", name="arm", source="") == "zenorbit/r-1/i/arm/o/"
    with pytest.raises(TypeError, match="no value for 'generation'"):
        protocol.COMMANDS.key("r-1", name="arm")


_ODD_JSON = (None, True, -1, 2**64, 1.5, float("nan"), "", "x", [], {}, [[1, "a"]], {"op": 1})


def _json_paths(value, path=()):
    """Every place in a JSON value: (path, value)."""
    yield path, value
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _json_paths(v, (*path, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _json_paths(v, (*path, i))


def _replaced(value, path, new):
    if not path:
        return new
    copy = dict(value) if isinstance(value, dict) else list(value)
    if new is _DELETE and len(path) == 1:
        del copy[path[0]]
    else:
        copy[path[0]] = _replaced(value[path[0]], path[1:], new)
    return copy


_DELETE = object()


def _framed_like(payload: bytes, body, blob: bytes) -> bytes:
    text = json.dumps(body).encode()
    return payload[:1] + struct.pack("<I", len(text)) + text + blob


def _structured_mutations(payload: bytes, rng):
    """The JSON object of a C/R/E/V message with each of its values (and keys) replaced by
    values of other types, or deleted, framed right; and its blob cut or grown."""
    if payload[:1] not in (
        protocol.CONTROL,
        protocol.REPLY,
        protocol.FAULT,
        protocol.EVENT,
        queries.REQUEST,
        queries.ANSWER,
    ):
        return
    (n,) = struct.unpack_from("<I", payload, 1)
    body, blob = json.loads(payload[5 : 5 + n]), payload[5 + n :]
    for path, _ in _json_paths(body):
        for odd in (*_ODD_JSON, _DELETE) if path else _ODD_JSON:
            yield _framed_like(payload, _replaced(body, path, odd), blob)
    for cut in range(1, min(len(blob), 16) + 1):
        yield _framed_like(payload, body, blob[:-cut])
    for grow in range(1, 17):
        yield _framed_like(payload, body, blob + rng.bytes(grow))
    for op in ("", "explode", "wire", "start", "terminate", "events", "swap", "status", "granted"):
        yield _framed_like(payload, {**body, "op": op}, blob)
    yield payload[:1] + struct.pack("<I", 20_000) + b"[" * 20_000  # nested too deep for json


def _fuzz_cases(payload: bytes, seed: int):
    """Deterministic (seeded) garbage near ``payload``: every truncation, bit flips, bytes replaced,
    inserted or deleted, random tails, random bytes, structured mutations."""
    rng = np.random.default_rng(seed)
    for n in range(len(payload)):
        yield payload[:n]
    for _ in range(1000):
        flipped = bytearray(payload)
        i = int(rng.integers(len(flipped)))
        flipped[i] ^= 1 << int(rng.integers(8))
        yield bytes(flipped)
    for _ in range(500):
        changed = bytearray(payload)
        for i in rng.integers(len(changed), size=int(rng.integers(1, 5))):
            changed[int(i)] = int(rng.integers(256))
        yield bytes(changed)
    for _ in range(300):
        i = int(rng.integers(len(payload) + 1))
        yield payload[:i] + rng.bytes(int(rng.integers(1, 5))) + payload[i:]
        yield payload[:i] + payload[i + int(rng.integers(1, 5)) :]
    for _ in range(300):
        yield payload + rng.bytes(int(rng.integers(1, 40)))
        yield payload[:1] + rng.bytes(int(rng.integers(0, 200)))
        yield rng.bytes(int(rng.integers(0, 200)))
    yield from _structured_mutations(payload, rng)


@pytest.mark.parametrize("kind", MESSAGES, ids=lambda kind: kind.__name__)
def test_every_message_decoder_decodes_or_raises_malformed_on_garbage(kind):
    """A few thousand cases per decoder; what decodes is a message of its declared types (it
    encodes again, to bytes that decode to the same message)."""
    payload = EXAMPLES[kind].encode()
    decoders = {kind.decode, DISPATCHERS.get(kind, kind.decode)}
    cases = rejected = 0
    for mutated in _fuzz_cases(payload, zlib.crc32(kind.__name__.encode())):
        for decode in decoders:
            cases += 1
            try:
                decoded = decode(mutated)
            except protocol.Malformed:
                rejected += 1
                continue
            # any other exception fails the test: it would have reached the run
            again = decoded.encode()
            assert decode(again).encode() == again, f"{kind.__name__}: {mutated!r:.200} decoded to {decoded!r:.200}"
    assert cases >= 2000 * len(decoders)
    assert rejected > 500, f"{kind.__name__}: only {rejected} of {cases} cases rejected; the decoder checks too little"


@pytest.mark.parametrize(
    "payload, message",
    [
        (b"C" + struct.pack("<I", 2) + b"{}", r"command: expected op one of instantiate, wire, .*, got None"),
        (
            b"E" + struct.pack("<I", 37) + b'{"op": "step", "k": "1", "error": ""}',
            r"Fault.k: expected an integer .*, got '1'",
        ),
        (protocol.Horizon(3).encode()[:-1], r"Horizon: expected b'H' and an int64 \(9 bytes\), got 8 bytes"),
        (
            protocol.Start([("a", 1, 2)], 5, np.zeros(3)).encode(),
            r"Start: expected held sizes >= 0 adding up to the 3 values",
        ),
        (
            protocol.Wire(0, 1, 1, 0, [], [], [_route("a", [0], [0], 0, 0)], {}, []).encode(),
            r"Wire.routes\[0\]: .* ratio 0",
        ),
        (
            protocol.Initialize(0, {}, np.zeros(2)).encode()[:-1],
            r"Initialize.inputs: expected float64 values .* got 15 bytes",
        ),
        (b"K!", r"Beat: expected the one byte b'K'"),
    ],
)
def test_a_malformed_message_says_which_and_what_was_expected(payload, message):
    decode = (
        protocol.decode_report
        if payload[:1] in (protocol.REPLY, protocol.FAULT, protocol.EVENT, protocol.BEAT)
        else protocol.decode_command
    )
    with pytest.raises(protocol.Malformed, match=message):
        decode(payload)


def test_keys_are_read_back_by_the_topics_that_spell_them():
    """The orchestrator reads who sent a batch, a reply or a liveliness token from its key with
    the same declaration that spelled it; any other key is refused (Malformed) or not a process's."""
    run = "r1"
    assert bus.batch_source(protocol.BATCHES.key(run, name="arm")) == "arm"
    assert bus.reply_source(protocol.REPLIES.key(run, name="arm", generation=12)) == ("arm", 12)
    assert bus.alive_source(protocol.ALIVE.key(run, name="arm", generation=3)) == ("arm", 3)
    assert bus.alive_source(protocol.ORCHESTRATOR_ALIVE.key(run)) is None
    assert bus.alive_source(protocol.ALIVE.key(run, name="arm", generation="²")) is None
    for key in (
        protocol.REPLIES.key(run, name="arm", generation="x"),
        protocol.BATCHES.key(run, name="arm") + "/x",
        f"zenorbit/{run}/c/arm/1/in",
        "elsewhere/r1/c/arm/1/out",
        protocol.BATCHES.key(run, name=""),
    ):
        with pytest.raises(bus.Malformed):
            bus.reply_source(key) if "/c/" in key else bus.batch_source(key)
    rng = np.random.default_rng(7)
    for template in (protocol.REPLIES, protocol.ALIVE, protocol.BATCHES, protocol.OUTPUTS, protocol.COMMANDS):
        key = template.key(
            run,
            **{
                f: "n1" if f == "name" else "4"
                for f in ("name", "generation", "source")
                if "{" + f + "}" in template.template
            },
        )
        for _ in range(300):  # a key cut or grown by chunks: read back as its fields or refused, never a crash
            chunks = key.split("/")
            cut = chunks[: rng.integers(1, len(chunks) + 1)] + ["x"] * int(rng.integers(0, 2))
            fields = template.fields("/".join(cut))
            assert fields is None or template.key(run, **fields) == "/".join(cut)
