"""A component process's step logic (components/process.py ComponentProcess) without the bus: its
three publish callbacks are lists, and the orchestrator's messages are handed to it directly."""

from __future__ import annotations

import numpy as np

from components import bus, protocol
from components.process import ComponentProcess, Halt
from components.sdk import RunSettings


class Transport:
    """What a ComponentProcess publishes: replies and faults, outputs, batches."""

    def __init__(self):
        self.replies, self.outputs, self.batches = [], [], []

    def process(self, name: str) -> ComponentProcess:
        return ComponentProcess(
            name, self.replies.append, lambda consumers, payload: self.outputs.append(payload), self.batches.append
        )

    def faults(self) -> list[dict]:
        return [protocol.Fault.decode(p) for p in self.replies if p[:1] == protocol.FAULT]

    def tags(self) -> list[int]:
        return [t for b in self.batches for t in bus.decode_batch(b)[1].tolist()]


def started(transport: Transport, params: dict) -> ComponentProcess:
    """test.faulty instantiated, wired (no inputs), initialized and started with horizon 0."""
    p = transport.process("f")
    p.command(protocol.Instantiate("test.faulty", params, RunSettings().to_json()).encode())
    p.command(
        protocol.Wire(
            generation=0,
            step_ns=1_000_000,
            ratio=1,
            k=0,
            consumers=[],
            batch_consumers=[],
            routes=[],
            sources={},
            faults=[],
        ).encode()
    )
    p.command(protocol.Initialize(0, {}, np.empty(0)).encode())
    p.command(protocol.Start([], 0, np.empty(0)).encode())
    return p


def step_until_halt(p: ComponentProcess) -> bool:
    try:
        p.advance()
    except Halt:
        return True
    return False


def test_a_step_that_failed_is_never_run_again_whatever_horizon_comes():
    """test.faulty raises at step 3: one fault for step 3, steps 0-2 published; a larger horizon
    granted after the fault (the orchestrator had sent it before it heard of the fault) runs no
    step, so the failed step is not retried past its injected fault and the run ends where it
    failed."""
    t = Transport()
    p = started(t, {"fault": "raise", "at_step": 3})
    p.command(protocol.Horizon(10).encode())
    assert step_until_halt(p)
    assert [(f.op, f.k) for f in t.faults()] == [("step", 3)]
    assert t.tags() == [1, 2, 3]
    p.command(protocol.Horizon(20).encode())
    assert not step_until_halt(p)
    assert len(t.faults()) == 1 and t.tags() == [1, 2, 3] and p.component.k == 3


def test_nan_output_halts_at_that_step():
    t = Transport()
    p = started(t, {"fault": "nan", "at_step": 2})
    p.command(protocol.Horizon(10).encode())
    assert step_until_halt(p)
    assert [(f.op, f.k, f.error) for f in t.faults()] == [("nan", 2, "y")]
    p.command(protocol.Horizon(30).encode())
    p.advance()
    assert t.tags() == [1, 2] and len(t.faults()) == 1


def test_a_healthy_component_steps_to_the_horizon_and_no_further():
    t = Transport()
    p = started(t, {"fault": "raise", "at_step": 100})
    p.command(protocol.Horizon(5).encode())
    assert not step_until_halt(p)
    assert t.tags() == [1, 2, 3, 4, 5] and not t.faults()
