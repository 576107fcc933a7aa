"""What a run holds as it goes, in one place: its inbox, its members, the recorded rows, the
horizon, what is still to happen (events, injected faults) and its last checkpoint. The parts
that drive the run (:mod:`.engine`, :mod:`.listener`, :mod:`.recovery`) read and change it here,
not in one another."""

from __future__ import annotations

import queue
from dataclasses import dataclass, field

import numpy as np

from components import schedule
from orchestrator.config.outcomes import declared
from orchestrator.config.specs import ComponentSpec, Event, Fault, RunConfig
from orchestrator.run import outcome
from orchestrator.run.members import Member
from orchestrator.run.rows import Rows


@dataclass
class Checkpoint:
    """Where a restart goes back to: a step boundary, every component's state there and what the
    orchestrator held (the recorded row, each member's last outputs)."""

    row: int
    values: np.ndarray
    specs: list[ComponentSpec]
    states: dict[str, bytes]
    latest: dict[str, tuple[int, np.ndarray]]
    events: list  # the config's swaps still to come
    outcome: tuple | None = None  # the outcome so far (outcome.Tracker.state)


@dataclass
class RunState:
    """``inbox``: every message the orchestrator receives (the bus callbacks only enqueue);
    ``joining``: a swap's new generation, until it takes over; ``horizon``: steps k < horizon are
    granted (``horizon_at``: since when)."""

    config: RunConfig
    rows: Rows
    pending_events: list[Event]
    pending_faults: list[Fault]
    inbox: queue.SimpleQueue = field(default_factory=queue.SimpleQueue)
    members: dict[str, Member] = field(default_factory=dict)
    joining: dict[str, Member] = field(default_factory=dict)
    horizon: int = 0
    horizon_at: float = 0.0
    checkpoint: Checkpoint | None = None
    restarts: int = 0
    stop_reason: str | None = None
    outcome: outcome.Tracker | None = None  # None: no component declares outcomes

    @classmethod
    def of(cls, config: RunConfig) -> RunState:
        """A run of ``config`` before it starts."""
        found = declared(config.components)
        return cls(
            config,
            Rows(config.components.values(), config.step_ns),
            list(config.events),
            list(config.faults),
            outcome=outcome.Tracker(found) if found else None,
        )

    def log(self, kind: str, **fields) -> None:
        """An event in events.jsonl, if the run is recorded; the outcome hears it, recorded or not."""
        if self.outcome is not None:
            self.outcome.hear(kind, fields)
        if self.rows.recording is not None:
            self.rows.recording.event(kind, **fields)

    def next_event_step(self) -> int | None:
        """The step of the config's next swap, or None."""
        if not self.pending_events:
            return None
        return schedule.first_step_at(self.pending_events[0].at_ns, self.config.step_ns)
