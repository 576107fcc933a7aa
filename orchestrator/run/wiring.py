"""Who feeds whom: the routes of a member's inputs, and the wire, initialize, start and rewire
messages that tell a member about them. The bodies are pure functions of the members and the
config; the few functions that send them say so."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from components import protocol, schedule
from components.constants import NS_PER_S
from components.schedule import Route
from orchestrator.config.specs import ComponentSpec, RunConfig
from orchestrator.config.specs import Fault as Injected  # an injected fault (not a reported one)
from orchestrator.run.members import Crew, Member, RunFailure


def routes(consumer: ComponentSpec, members: dict[str, Member], config: RunConfig) -> list[Route]:
    return schedule.routes(
        consumer.name,
        consumer.inputs.offsets,
        config.connections,
        {n: m.spec.outputs.offsets for n, m in members.items()},
        {n: m.ratio for n, m in members.items()},
        list(config.components),
        config.algorithm,
    )


def frame_routes(consumer: ComponentSpec, members: dict[str, Member], config: RunConfig) -> list[schedule.FrameRoute]:
    return schedule.frame_routes(
        consumer.name,
        [v.name for v in consumer.inputs.frames],
        config.connections,
        {n: m.ratio for n, m in members.items()},
        list(config.components),
        config.algorithm,
    )


def wire_message(
    member: Member, members: dict[str, Member], config: RunConfig, faults: Sequence[Injected], k: int
) -> protocol.Wire:
    """Which sources feed which of ``member``'s inputs (its routes, set), whom it feeds, from step
    ``k``, and the faults to inject into it."""
    name, step_ns = member.name, config.step_ns
    batched = schedule.batch_consumers(name, config.connections)
    return protocol.Wire(
        generation=member.generation,
        step_ns=step_ns,
        ratio=member.ratio,
        k=k,
        consumers=sorted({d for d, _, s, _ in config.connections if s == name and d != name} - set(batched)),
        batch_consumers=batched,
        routes=member.routes,
        sources=sources(member, members),
        faults=[
            (schedule.first_step_at(f.at_ns, step_ns), f.kind, (f.duration_ns or 0) / NS_PER_S)
            for f in faults
            if f.component == name
        ],
        frame_routes=[
            (r.source, r.output, r.input, r.ratio, r.ahead) for r in frame_routes(member.spec, members, config)
        ],
        frame_consumers=schedule.frame_consumers(
            name, [v.name for v in member.spec.outputs.frames], config.connections
        ),
    )


def sources(member: Member, members: dict[str, Member]) -> dict[str, int]:
    """The generation of each of ``member``'s sources (of floats or frames)."""
    return {r.source: members[r.source].generation for r in [*member.routes, *member.frame_routes]}


def held(member: Member, members: dict[str, Member], only: str | None = None) -> list[tuple[str, int, np.ndarray]]:
    """What ``member``'s sources (or just ``only``) hold now: the recorded outputs and any
    published ahead of them, as (source, tag, outputs) for a ``start``/``rewire`` message."""
    entries = []
    for name in {r.source for r in member.routes if only in (None, r.source)}:
        source = members[name]
        for tag, vector in [(source.tag, source.latest), *source.received]:
            entries.append((name, tag, vector))
    return entries


def initial_inputs(member: Member, members: dict[str, Member], step_ns: int) -> tuple[np.ndarray, dict]:
    """``member``'s inputs at initialization, from what its sources hold, and when each was sampled
    (only inputs from an initialized source have a time)."""
    inputs = member.spec.inputs.start_vector()
    times = {}
    for route in member.routes:
        source = members[route.source]
        inputs[route.dst] = source.latest[route.src]
        if source.initialized:
            times.update(dict.fromkeys(schedule.fed_inputs(route, member.spec.inputs.offsets), source.tag * step_ns))
    return inputs, times


def wire(crew: Crew, member: Member, members: dict[str, Member], faults: Sequence[Injected], k: int) -> None:
    """Route ``member``'s inputs and send it the wire message; wait for its answer."""
    config = crew.config
    member.routes = routes(member.spec, members, config)
    member.frame_routes = frame_routes(member.spec, members, config)
    crew.ask([member], wire_message(member, members, config, faults, k), "wire", config.start_timeout_s)


def initialize(crew: Crew, member: Member, members: dict[str, Member], t_ns: int) -> np.ndarray:
    """Initialize ``member`` at ``t_ns``; its outputs there, all finite (else RunFailure)."""
    inputs, times = initial_inputs(member, members, crew.config.step_ns)
    crew.ask([member], protocol.Initialize(t_ns, times, inputs), "initialize", crew.config.start_timeout_s)
    vector = np.frombuffer(member.answer().blob, dtype=np.float64)
    variable = member.spec.outputs.first_non_finite(vector)
    if variable is not None:
        raise RunFailure(
            f"component {member.name!r} produced a non-finite value in output {variable!r} "
            f"after initialize (t = {t_ns / NS_PER_S:g} s)"
        )
    return vector


def go(member: Member, members: dict[str, Member], horizon: int) -> None:
    """Let ``member`` step, from what its sources hold, below ``horizon``."""
    entries, values = protocol.holding(held(member, members))
    member.control(protocol.Start(entries, horizon, values))


def rewire(consumer: Member, members: dict[str, Member], config: RunConfig, source: str) -> None:
    """Tell ``consumer`` that ``source`` has a new generation (its routes may change with the type)."""
    consumer.routes = routes(consumer.spec, members, config)
    consumer.frame_routes = frame_routes(consumer.spec, members, config)
    entries, values = protocol.holding(held(consumer, members, only=source))
    consumer.control(protocol.Rewire(entries, consumer.routes, sources(consumer, members), values))
