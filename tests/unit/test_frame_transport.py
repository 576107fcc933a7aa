"""Frames on the bus (components/process.py, components/bus.py): a frame's bytes arrive bit for bit,
and a consumer steps k only once the frame tagged for k is held, whatever order the messages come
in, giving the numbers of the same components stepped by hand (the harness). No Zenoh: the
processes' publish callbacks are lists, their messages handed on directly."""

from __future__ import annotations

import numpy as np
import pytest

from components import bus, protocol
from components.process import ComponentProcess
from components.sdk import RunSettings
from components.testing.harness import Harness

STEP_NS = 1_000_000
SIZE = {"width": 40, "height": 30}


def test_a_frame_survives_encoding_bit_for_bit():
    rng = np.random.default_rng(7)
    rgb = rng.integers(0, 256, (30, 40, 3), dtype=np.uint8)
    depth = rng.standard_normal((30, 40)).astype(np.float32)
    depth[3, 4] = np.nan
    for frame in (rgb, depth, rgb[:, :, 0]):
        generation, tag, output, back = bus.decode_frame(bus.encode_frame(2, 17, "ímage", frame))
        assert (generation, tag, output) == (2, 17, "ímage")
        assert back.dtype == frame.dtype and back.shape == frame.shape and back.tobytes() == frame.tobytes()
        assert not back.flags.writeable


@pytest.mark.parametrize("cut", [1, 40, -1])
def test_a_frame_message_of_the_wrong_length_is_malformed(cut):
    payload = bus.encode_frame(0, 1, "rgb", np.zeros((30, 40, 3), dtype=np.uint8))
    with pytest.raises(protocol.Malformed):
        bus.decode_frame(payload[:cut] if cut > 0 else payload + b"\0")


def process(name: str, kind: str, sent: list, **wire) -> ComponentProcess:
    p = ComponentProcess(name, lambda payload: None, lambda consumers, payload: sent.append(payload), sent.append)
    p.command(protocol.Instantiate(kind, SIZE, RunSettings().to_json()).encode())
    p.command(
        protocol.Wire(
            generation=0, step_ns=STEP_NS, ratio=wire.pop("ratio", 1), k=0, batch_consumers=[], faults=[], **wire
        ).encode()
    )
    p.command(protocol.Initialize(0, {}, np.zeros(p.inputs.size)).encode())
    return p


def camera_messages(steps: int) -> list[bytes]:
    """What test.imager (step 2 run steps) sends its consumer: sync, then per step its two frames and its outputs."""
    sent: list[bytes] = []
    camera = process(
        "camera",
        "test.imager",
        sent,
        ratio=2,
        consumers=["reader"],
        routes=[],
        sources={},
        frame_consumers={"rgb": ["reader"], "depth": ["reader"]},
    )
    camera.command(protocol.Sync().encode())
    camera.command(protocol.Start([], 2 * steps, np.empty(0)).encode())
    camera.advance()
    return [m for m in sent if m[:1] != bus.BATCH]  # those go to the orchestrator


def test_the_producer_sends_each_frame_before_its_steps_outputs():
    kinds = [(m[:1], bus.decode_frame(m)[1] if m[:1] == bus.FRAME else None) for m in camera_messages(3)]
    # initialize's frames (tag 0) again at sync, then per step: rgb, depth, outputs
    assert [k for k, _ in kinds] == [b"F", b"F", b"Y"] + [b"F", b"F", b"O"] * 3
    assert [t for _, t in kinds if t is not None] == [0, 0, 2, 2, 4, 4, 6, 6]


def reader(sent: list) -> ComponentProcess:
    # steps every run step, reads the camera's frames (step 2): tags 0, 0, 2, 2, 4, ...
    p = process(
        "reader",
        "test.image_sum",
        sent,
        consumers=[],
        routes=[],
        sources={"camera": 0},
        frame_routes=[("camera", "rgb", "rgb", 2, 0), ("camera", "depth", "depth", 2, 0)],
    )
    return p


def by_hand(steps: int) -> list[np.ndarray]:
    """The reader's outputs with the harness: the camera's frames of each tag set as inputs."""
    camera, image_sum = Harness("test.imager", SIZE), Harness("test.image_sum", SIZE)
    camera.initialize()
    image_sum.initialize()
    frames, rows = {0: dict(camera.frames)}, []
    for tag in range(2, 2 * steps + 1, 2):
        camera.step(2 * STEP_NS)
        frames[tag] = dict(camera.frames)
    for k in range(2 * steps):
        image_sum.inputs.update(frames[k // 2 * 2])
        image_sum.input_times_ns = {"rgb": k // 2 * 2 * STEP_NS}
        out = image_sum.step(STEP_NS)
        rows.append(np.array([out["s"], out["d"], out["t_image"]]))
    return rows


def recorded(sent: list[bytes]) -> list[np.ndarray]:
    """The outputs of each step, from the batches sent for the recording."""
    return [row.copy() for m in sent if m[:1] == bus.BATCH for row in bus.decode_batch(m)[3]]


def test_late_and_reordered_frames_give_the_numbers_of_the_frames_in_order():
    """The camera's messages delivered with every step's frames after its outputs and the frames
    of two steps swapped: the reader waits for each frame and its numbers are the harness's."""
    messages = [m for m in camera_messages(4) if m[:1] != bus.OUTPUT]  # the reader reads no float of the camera
    sync, frames = messages[2], [m for m in messages if m[:1] == bus.FRAME]
    swapped = frames[:2] + frames[4:6] + frames[2:4] + frames[6:]  # tag 4's frames before tag 2's
    sent: list[bytes] = []
    p = reader(sent)
    p.source_output("camera", sync)
    p.command(protocol.Start([], 8, np.empty(0)).encode())
    progress = []
    for message in swapped:
        p.source_output("camera", message)
        p.advance()
        progress.append(p.next_k)
    # tag 0 (steps 0, 1) needs both of its frames; tag 4's frames do not let steps 2, 3 run
    assert progress == [0, 2, 2, 2, 2, 6, 6, 8, 8, 8]
    expected = by_hand(4)
    p.flush()
    got = recorded(sent)
    assert len(got) == 8 and all(np.array_equal(g, e) for g, e in zip(got, expected))
    assert len({float(row[0]) for row in got}) == 4  # each tag's frame gave other numbers


def test_a_frame_input_holds_zeros_at_initialize_and_is_read_only_in_a_step():
    sent: list[bytes] = []
    p = reader(sent)
    assert not p.input_views["rgb"].any() and not p.input_views["rgb"].flags.writeable
    h = Harness("test.image_sum", SIZE)
    h.inputs["rgb"] = np.full((30, 40, 3), 255, dtype=np.uint8)
    assert h.initialize()["d"] == 0.0  # a frame is first read at a step
    assert h.step(STEP_NS)["s"] == pytest.approx(float(np.arange(1, 3601) @ np.full(3600, 255.0)) / 9973.0 % 1.0)
