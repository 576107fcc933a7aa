"""Every decoder of the wire protocol, fuzzed: a well-formed message decodes to what was encoded,
and anything else (random bytes, truncations, bit flips, wrong lengths) raises bus.Malformed and
nothing else, so whoever can reach the bus cannot crash a run."""
import numpy as np
import pytest

from components import bus

RNG = np.random.default_rng(20261124)


def _valid_messages() -> dict[str, bytes]:
    outputs = np.arange(12.0).reshape(3, 4)
    return {
        "output": bus.encode_output(2, 7, outputs[0]),
        "batch": bus.encode_batch(2, np.array([5, 6, 7]), np.ones((3, 2)), outputs),
        "sync": bus.encode_sync(3),
        "horizon": bus.encode_horizon(40),
        "control": bus.encode_message(bus.CONTROL, {"op": "set_state"}, bus.encode_state({"x": np.ones(3)})),
        "fault": bus.encode_message(bus.FAULT, {"op": "step", "k": 4, "error": "boom"}),
    }


DECODERS = {
    "output": bus.decode_output,
    "batch": bus.decode_batch,
    "sync": bus.decode_sync,
    "horizon": bus.decode_horizon,
    "control": bus.decode_message,
    "fault": lambda b: bus.decode_message(b, bus.FAULT_FIELDS),
    "state": bus.decode_state,
}


def test_well_formed_messages_decode_to_what_was_encoded():
    m = _valid_messages()
    generation, tag, vector = bus.decode_output(m["output"])
    assert (generation, tag, vector.tolist()) == (2, 7, [0.0, 1.0, 2.0, 3.0])
    generation, tags, timings, outputs = bus.decode_batch(m["batch"])
    assert generation == 2 and tags.tolist() == [5, 6, 7] and outputs[2].tolist() == [8.0, 9.0, 10.0, 11.0]
    assert bus.decode_sync(m["sync"]) == 3 and bus.decode_horizon(m["horizon"]) == 40
    body, blob = bus.decode_message(m["control"])
    assert body == {"op": "set_state"} and bus.decode_state(blob)["x"].tolist() == [1.0, 1.0, 1.0]
    assert bus.decode_message(m["fault"], bus.FAULT_FIELDS)[0]["k"] == 4


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
    yield b"\x00\x01\x02"   # the 3 bytes that used to end a run


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


@pytest.mark.parametrize("payload, message", [
    (bus.encode_batch(0, np.array([3, 2]), np.zeros((2, 2)), np.zeros((2, 1))), "not increasing"),
    (bus.encode_batch(0, np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros((0, 3))), "does not hold 0 steps"),
    (bus.encode_batch(0, np.array([1]), np.zeros((1, 2)), np.zeros((1, 3)))[:-8], "does not hold"),
    (bus.encode_output(0, 1, np.zeros(2))[:-3], "whole number of float64"),
    (bus.encode_message(bus.FAULT, {"op": "step", "k": "4", "error": "x"}), "lacks k"),
    (bus.encode_message(bus.FAULT, [1, 2]), "not a JSON object"),
])
def test_malformed_says_what_is_wrong(payload, message):
    with pytest.raises(bus.Malformed, match=message):
        (bus.decode_batch if payload[:1] == bus.BATCH else bus.decode_output if payload[:1] == bus.OUTPUT
         else lambda b: bus.decode_message(b, bus.FAULT_FIELDS))(payload)
