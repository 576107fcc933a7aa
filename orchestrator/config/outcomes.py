"""What a run may come to: the outcomes the first of its components whose type declares any
(``Component.outcomes``; a shadow never) gives, and whether ``run.expect`` names one of them.
:mod:`orchestrator.run.outcome` decides which one a run comes to."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from components.sdk import Outcome


@dataclass(frozen=True)
class Declared:
    """The outcomes of a run: those of ``component`` (of type ``type``)."""

    component: str
    type: str
    outcomes: tuple[Outcome, ...]

    @property
    def names(self) -> list[str]:
        return [o.name for o in self.outcomes]

    def problem(self, expect: str) -> str | None:
        """Why ``expect`` cannot be this run's outcome (None: it can)."""
        if expect in self.names:
            return None
        return f"{expect!r} is not an outcome of {self.component} ({self.type}); its outcomes: {', '.join(self.names)}"


def declared(components: Mapping[str, Any]) -> Declared | None:
    """The run's outcomes from its components (name -> ComponentSpec), None when no type declares any."""
    for name, spec in components.items():
        if not spec.shadow_of and spec.cls.outcomes:
            return Declared(name, spec.type, tuple(spec.cls.outcomes))
    return None


def expect_problem(components: Mapping[str, Any], expect: str) -> str | None:
    """Why a run of these components cannot be expected to end in ``expect`` (None: it can)."""
    found = declared(components)
    if found is None:
        types = ", ".join(sorted({s.type for s in components.values()}))
        return f"{expect!r}: no component of this run declares outcomes (its types: {types})"
    return found.problem(expect)
