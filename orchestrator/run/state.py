"""What a run holds as it goes, in one place: its inbox, its members, the recorded rows, the
horizon, what is still to happen (events, injected faults) and its last checkpoint. The parts
that drive the run (:mod:`.engine`, :mod:`.loop`, :mod:`.listener`, :mod:`.recovery`) read it
here, not in one another, and change it only through its methods, each keeping it consistent."""

from __future__ import annotations

import queue
from dataclasses import dataclass

import numpy as np

from components import schedule
from orchestrator.config.outcomes import declared
from orchestrator.config.specs import ComponentSpec, Event, Fault, RunConfig
from orchestrator.run import outcome
from orchestrator.run.members import Member
from orchestrator.run.rows import Rows


@dataclass(frozen=True)
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


def faults_left(faults: list[Fault], failed: str, horizon: int, row: int, step_ns: int) -> list[Fault]:
    """The injected faults still to come after a restart from ``row``: an injected fault fires
    once, so neither the one behind this failure (of ``failed``, below ``horizon``) nor those the
    run went past (before ``row``) are left."""

    def step(f: Fault) -> int:
        return schedule.first_step_at(f.at_ns, step_ns)

    cause = next((f for f in faults if f.component == failed and step(f) <= horizon), None)
    return [f for f in faults if f is not cause and step(f) >= row]


class RunState:
    """``inbox``: every message the orchestrator receives (the bus callbacks only enqueue);
    ``members``: the live members by name, ``joining``: a swap's new generation until it takes
    over (the crew registers the members it starts in one or the other); ``horizon``: steps k <
    horizon are granted (``horizon_at``: since when, monotonic s)."""

    def __init__(self, config: RunConfig, rows: Rows, events: list[Event], faults: list[Fault], tracker=None):
        self.config, self.rows = config, rows
        self.inbox: queue.SimpleQueue = queue.SimpleQueue()
        self.members: dict[str, Member] = {}
        self.joining: dict[str, Member] = {}
        self._events, self._faults = list(events), list(faults)
        self._horizon, self._horizon_at = 0, 0.0
        self._checkpoint: Checkpoint | None = None
        self._restarts = 0
        self._stop_reason: str | None = None
        self._outcome: outcome.Tracker | None = tracker  # None: no component declares outcomes

    @classmethod
    def of(cls, config: RunConfig) -> RunState:
        """A run of ``config`` before it starts."""
        found = declared(config.components)
        return cls(
            config,
            Rows(config.components.values(), config.step_ns),
            config.events,
            config.faults,
            outcome.Tracker(found) if found else None,
        )

    # ------------------------------------------------------------------------ read

    @property
    def horizon(self) -> int:
        return self._horizon

    @property
    def horizon_at(self) -> float:
        return self._horizon_at

    @property
    def checkpoint(self) -> Checkpoint | None:
        return self._checkpoint

    @property
    def restarts(self) -> int:
        return self._restarts

    @property
    def stop_reason(self) -> str | None:
        return self._stop_reason

    @property
    def outcome(self) -> outcome.Tracker | None:
        return self._outcome

    @property
    def pending_faults(self) -> tuple[Fault, ...]:
        """The injected faults still to come."""
        return tuple(self._faults)

    def next_event_step(self) -> int | None:
        """The step of the config's next swap, or None."""
        if not self._events:
            return None
        return schedule.first_step_at(self._events[0].at_ns, self.config.step_ns)

    def log(self, kind: str, **fields) -> None:
        """An event in events.jsonl, if the run is recorded; the outcome hears it, recorded or not."""
        if self._outcome is not None:
            self._outcome.hear(kind, fields)
        if self.rows.recording is not None:
            self.rows.recording.event(kind, **fields)

    # ---------------------------------------------------------------------- change

    def grant(self, horizon: int, now: float) -> None:
        """Steps k < ``horizon`` may run, from ``now`` on; the horizon never goes back (but in a restart)."""
        if horizon < self._horizon:
            raise ValueError(f"the horizon goes back from {self._horizon} to {horizon} outside a restart")
        self._horizon, self._horizon_at = horizon, now

    def stop(self, reason: str) -> None:
        """End the run at its next step boundary, for ``reason`` (events.jsonl's end status)."""
        if not reason:
            raise ValueError("a stop needs a reason")
        self._stop_reason = reason

    def take_due_event(self) -> Event | None:
        """The config's next swap if it is due at this row (taken off those to come), else None."""
        step = self.next_event_step()
        return self._events.pop(0) if step is not None and step <= self.rows.row else None

    def keep_checkpoint(self, states: dict[str, bytes]) -> Checkpoint:
        """This step boundary, where every member is (the horizon), as the one a restart goes back
        to: ``states`` holds every live member's state, by name."""
        if self.rows.row != self._horizon:
            raise ValueError(f"a checkpoint at row {self.rows.row}, not at the horizon {self._horizon}")
        if states.keys() != self.members.keys():
            raise ValueError(f"a checkpoint with the states of {sorted(states)}, not of {sorted(self.members)}")
        live = list(self.members.values())
        self._checkpoint = Checkpoint(
            self.rows.row,
            self.rows.values.copy(),
            [m.spec for m in live],
            dict(states),
            {m.name: (m.tag, m.latest.copy()) for m in live},
            list(self._events),
            self._outcome.state() if self._outcome else None,
        )
        return self._checkpoint

    def take_over(self, name: str) -> Member:
        """The joining generation of ``name`` becomes the live one; the one it replaces."""
        new, old = self.joining.get(name), self.members.get(name)
        if new is None or old is None or new.generation <= old.generation:
            raise ValueError(f"no newer generation of {name!r} joining to take over")
        self.members[name] = self.joining.pop(name)
        return old

    def drop_joining(self, name: str) -> Member | None:
        """A joining generation that will not take over (its swap failed); None if none was joining."""
        return self.joining.pop(name, None)

    def begin_restart(self, failed: str) -> dict[str, int]:
        """The run's processes stopped (by the caller) after ``failed`` died or hung: count the
        restart, forget every member and joining generation, keep the injected faults still to
        come from the checkpoint on; the generation each member starts again with."""
        if self._checkpoint is None:
            raise ValueError("a restart without a checkpoint to go back to")
        generations = {n: m.generation + 1 for n, m in self.members.items()}
        self._restarts += 1
        self._faults = faults_left(self._faults, failed, self._horizon, self.rows.row, self.config.step_ns)
        self.members, self.joining = {}, {}
        return generations

    def restart_from_checkpoint(self, now: float) -> None:
        """The new members (restored to the checkpoint's states) stand where the checkpoint was:
        their last outputs, the recorded rows, the horizon, the events to come and the outcome so
        far go back to it."""
        checkpoint = self._checkpoint
        if checkpoint is None or self.members.keys() != checkpoint.latest.keys():
            raise ValueError(
                f"a restart of {sorted(self.members)} from a checkpoint of "
                f"{sorted(checkpoint.latest) if checkpoint else 'none'}"
            )
        for member in self.members.values():
            tag, latest = checkpoint.latest[member.name]
            member.tag, member.latest, member.initialized = tag, latest.copy(), True
            member.progress, member.progress_at = checkpoint.row, now
        self.rows.rewind(checkpoint.row, checkpoint.values)
        self._horizon, self._horizon_at = checkpoint.row, now
        self._events = list(checkpoint.events)
        if (
            self._outcome is not None and checkpoint.outcome is not None
        ):  # events after the checkpoint come again (or not) in the rerun
            self._outcome.restore(checkpoint.outcome)
