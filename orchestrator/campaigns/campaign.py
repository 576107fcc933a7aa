"""Campaigns (``orchestrator sweep``): a base config, a grid and dispersions over its keys, and
metrics reduced from each case's signals (README "Parameter sweeps and Monte Carlo campaigns").

This module is the pure part: a campaign and its cases (:mod:`orchestrator.campaigns.dispersions`,
:mod:`orchestrator.campaigns.metrics`). Reading and validating a campaign file is
:mod:`orchestrator.campaigns.campaign_file`; running the cases is :mod:`orchestrator.campaigns.runner`.

A campaign file::

    config: ../configs/gravity_gradient_libration.yaml   # relative to this file, or a config inline
    samples: 20
    seed: 7
    grid: {run.step: [5 s, 10 s]}                         # the cartesian product of the lists
    disperse:
      components.dynamics.parameters.bodies.target.twist[5]: {normal: [0 rad/s, 1e-4 rad/s]}
    metrics:
      final_rate: {signal: dynamics.target.twist, reduce: final}      # a vector: its norm
      t_cross: {signal: dynamics.target.twist[5], reduce: first_crossing, threshold: 1e-4 rad/s}
      force: {signal: dynamics.grasp.wrench[0:3], reduce: max}        # a slice: the norm of the force
      t_capture: {event: capture, field: time}                        # an event's field (NaN: no event)
    outcomes: {captured: capture, aborted: capture_aborted}   # the last of these events names the outcome
                                                          # (none: the outcome its run declares, else completed)
    keep: failed                                          # all | failed | none

Cases: each grid point (in order) times ``samples`` draws; case ``i`` is grid point
``i // samples`` and draw ``i % samples``. The draw of a dispersed key depends only on the seed,
the draw's index and the key (numpy ``SeedSequence(seed, spawn_key=(draw, crc32(key)))``), so a
case reproduces by itself, adding a dispersed key leaves the others' draws alone, and every grid
point sees the same dispersions (common random numbers).
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from components.errors import ConfigError
from components.units import parse_quantity, parse_unit
from orchestrator.campaigns.dispersions import Dispersion
from orchestrator.campaigns.metrics import Metric

_KEY_PART = re.compile(r"^([A-Za-z0-9_\-]+)((?:\[\d+\])*)$")


# ---------------------------------------------------------------- keys and values


def key_path(key: str) -> list[str | int]:
    """``a.b[2].c`` -> ["a", "b", 2, "c"]; ValueError for anything else."""
    if not isinstance(key, str) or not key:
        raise ValueError("expected a config key like run.duration or components.c.parameters.x[0]")
    path: list[str | int] = []
    for part in key.split("."):
        m = _KEY_PART.match(part)
        if not m:
            raise ValueError(f"{part!r} is not a key part (a name, then optional [index]es)")
        path.append(m.group(1))
        path += [int(i) for i in re.findall(r"\[(\d+)\]", m.group(2))]
    return path


def set_key(raw: dict, key: str, value: Any) -> None:
    """Set ``key`` (as ``--set`` takes it, plus ``[i]`` into lists) in a raw config; ValueError if
    the path does not lead there (no such component, an index past a list's end, not a mapping)."""
    path = key_path(key)
    components = raw.get("components")
    if path[0] == "components" and len(path) > 2 and isinstance(components, dict) and path[1] not in components:
        raise ValueError(f"no component {path[1]!r} (components: {', '.join(map(str, components)) or 'none'})")
    node: Any = raw
    for i, part in enumerate(path[:-1]):
        here = _text(path[: i + 1])
        if isinstance(part, int):
            if not isinstance(node, list) or part >= len(node):
                raise ValueError(
                    f"{_text(path[:i])} is not a list with an element [{part}] in the config "
                    f"(give it in full in the base config)"
                )
            node = node[part]
            continue
        if not isinstance(node, dict):
            raise ValueError(f"{_text(path[:i])} is not a mapping")
        child = node.get(part)
        if child is None:
            if isinstance(path[i + 1], int):
                raise ValueError(f"{here} is not in the config: give it in full in the base config to set one element")
            child = node[part] = {}
        node = child
    last = path[-1]
    if isinstance(last, int):
        if not isinstance(node, list) or last >= len(node):
            raise ValueError(
                f"{_text(path[:-1])} is not a list with an element [{last}] in the config "
                f"(give it in full in the base config)"
            )
    elif not isinstance(node, dict):
        raise ValueError(f"{_text(path[:-1])} is not a mapping")
    node[last] = value


def _text(path: list) -> str:
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else part)
    return out


def si_value(value: Any) -> Any:
    """A parameter value as a number where it is one: a bare number, or ``"2 kg"`` in SI; else as given."""
    if isinstance(value, bool):
        return value
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, str):
        try:
            number, unit = parse_quantity(value, "")
        except ConfigError:
            return value
        return number * (parse_unit(unit)[0] if unit else 1.0)
    return value


# ---------------------------------------------------------------- the campaign


@dataclass
class Case:
    index: int
    params: dict[str, Any]  # key -> value as put in the config (with its unit)
    raw: dict  # the case's config, paths absolute


@dataclass
class Campaign:
    path: Path  # the campaign file (or where an inline config is taken from)
    base: dict  # the base config, raw, relative paths made absolute
    base_path: Path  # relative paths in the base config were relative to its directory
    grid: dict[str, list]
    dispersions: list[Dispersion]
    samples: int
    seed: int
    metrics: list[Metric]
    keep: str
    raw: dict = field(default_factory=dict)  # the campaign as read
    outcomes: dict[str, str] = field(default_factory=dict)  # outcome name -> the event that makes it

    def outcome(self, status: str, events: list[str], declared: str = "") -> str:
        """A case's outcome: failed (or interrupted) as its run; else the outcome whose event came
        last among ``outcomes``; else the one its run's components declare (``declared``: the
        capture's captured, aborted, undecided); else completed."""
        if status != "completed":
            return status
        by_event = {event: name for name, event in self.outcomes.items()}
        for event in reversed(events):
            if event in by_event:
                return by_event[event]
        return declared or status

    @property
    def count(self) -> int:
        points = 1
        for values in self.grid.values():
            points *= len(values)
        return points * self.samples

    @property
    def keys(self) -> list[str]:
        return list(self.grid) + [d.key for d in self.dispersions]

    def case(self, index: int) -> Case:
        """Case ``index``: grid point ``index // samples``, draw ``index % samples``."""
        if not 0 <= index < self.count:
            raise IndexError(f"case {index}: the campaign has cases 0..{self.count - 1}")
        point, draw = divmod(index, self.samples)
        params: dict[str, Any] = {}
        if self.grid:
            combos = list(itertools.product(*self.grid.values()))
            params.update(zip(self.grid, copy.deepcopy(combos[point])))
        for d in self.dispersions:
            params[d.key] = d.draw(self.seed, draw)
        raw = copy.deepcopy(self.base)
        for key, value in params.items():
            set_key(raw, key, value)
        return Case(index, params, raw)

    def fingerprint(self) -> str:
        """A hash of what decides the cases and their results (for --resume)."""
        text = json.dumps(
            {
                "base": self.base,
                "grid": self.grid,
                "disperse": [repr(d) for d in self.dispersions],
                "samples": self.samples,
                "seed": self.seed,
                "metrics": [repr(m) for m in self.metrics],
                "keep": self.keep,
                "outcomes": self.outcomes,
            },
            sort_keys=True,
            default=str,
        )
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def case_yaml(case: Case, campaign: Campaign) -> str:
    """The case's config as a YAML file (it runs by itself: ``orchestrator run`` it)."""
    head = (
        f"# case {case.index} of the campaign {campaign.path}\n"
        + "".join(f"#   {k}: {json.dumps(v, default=str)}\n" for k, v in case.params.items())
        + "# relative paths of the base config are made absolute\n"
    )
    return head + yaml.safe_dump(case.raw, sort_keys=False, default_flow_style=None, width=120)
