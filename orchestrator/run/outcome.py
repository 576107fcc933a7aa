"""The run's outcome: what a component type declares it may come to (``Component.outcomes``, e.g.
controller.capture's captured, aborted, undecided), decided from that component's own events.

The first component in config order whose type declares outcomes (a shadow never) gives them; at
the end the last of its events that decides an outcome names it, and with none the first outcome
declared holds. The summary line states it, events.jsonl's end event records it (``outcome``,
``outcome_text``), ``run --expect NAME`` (``run.expect``) exits 3 when it differs.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from components.sdk import Outcome
from orchestrator.config.outcomes import Declared

EXPECT_MISMATCH = 3  # the exit code of a run whose outcome is not the one expected


@dataclass
class Tracker:
    """The outcome so far, as the declaring component's events come in."""

    declared: Declared
    outcome: Outcome = field(init=False)  # the first declared until an event decides another
    fields: dict = field(default_factory=dict)

    def __post_init__(self):
        self.outcome = self.declared.outcomes[0]
        self._by_event = {e: o for o in self.declared.outcomes for e in o.events}

    def hear(self, kind: str, fields: Mapping[str, Any]) -> None:
        """An event of the run (its fields name the component that emitted it)."""
        if fields.get("component") == self.declared.component and kind in self._by_event:
            self.outcome, self.fields = self._by_event[kind], dict(fields)

    def state(self) -> tuple[Outcome, dict]:
        """What a checkpoint keeps (a restart goes back to it)."""
        return self.outcome, dict(self.fields)

    def restore(self, state: tuple[Outcome, dict]) -> None:
        self.outcome, self.fields = state[0], dict(state[1])

    def result(self, end_s: float) -> tuple[str, str]:
        """(name, the summary line's words) at the run's end ``end_s`` (s)."""
        return self.outcome.name, self.outcome.text(self.fields, end_s)


def derive(found: Declared, events: Iterable[Mapping[str, Any]], end_s: float) -> tuple[str, str]:
    """The outcome of a run from its events (events.jsonl's lines, in order): (name, words)."""
    tracker = Tracker(found)
    for event in events:
        tracker.hear(event.get("event", ""), event)
    return tracker.result(end_s)
