"""Campaigns (``orchestrator sweep``): a base config, a grid and dispersions over its keys, and
metrics reduced from each case's signals (README "Parameter sweeps and Monte Carlo campaigns").

This module is the pure part: reading and validating a campaign file, generating its cases and
reducing metrics from a recording (:mod:`orchestrator.campaigns.dispersions`, :mod:`orchestrator.campaigns.metrics`).
Running them is :mod:`orchestrator.campaigns.runner`.

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
from orchestrator.campaigns.dispersions import Dispersion, dispersion
from orchestrator.campaigns.metrics import Metric, metric, signals_of
from orchestrator.config.load import validate
from orchestrator.config.yaml_file import ConfigErrors, read_yaml

CAMPAIGN_KEYS = ("config", "grid", "disperse", "samples", "seed", "metrics", "outcomes", "keep")
RESERVED_OUTCOMES = ("completed", "failed", "interrupted")
KEEP = ("all", "failed", "none")
_KEY_PART = re.compile(r"^([A-Za-z0-9_\-]+)((?:\[\d+\])*)$")


class CampaignErrors(Exception):
    """Every problem of a campaign file, each ``file: key: message``."""

    def __init__(self, errors: list[str]):
        super().__init__("\n".join(errors))
        self.errors = errors


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


def absolute_paths(node: Any, base_dir: Path) -> Any:
    """Strings that name an existing file or directory relative to ``base_dir`` (``../models/x.urdf``)
    made absolute, so that a case's config runs from anywhere."""
    if isinstance(node, dict):
        return {k: absolute_paths(v, base_dir) for k, v in node.items()}
    if isinstance(node, list):
        return [absolute_paths(v, base_dir) for v in node]
    if (
        isinstance(node, str)
        and node
        and not node.startswith("/")
        and "://" not in node
        and ("/" in node or "." in node)
        and "\n" not in node
        and len(node) < 4096
    ):
        try:
            candidate = base_dir / node
            if candidate.exists():
                return str(candidate.resolve())
        except OSError:
            pass
    return node


def load_campaign(path: str | Path, *, check_cases: bool | list[int] = True) -> Campaign:
    """Read and validate a campaign: its own keys, then every case's config against the config
    schema (``check_cases``: True for all, or a list of case indexes). CampaignErrors lists
    every problem, each naming its key."""
    path = Path(path)
    try:
        raw = read_yaml(path)
    except ConfigErrors as e:
        raise CampaignErrors(
            [m.replace("with run, components, connections", "with config, grid, disperse, metrics") for m in e.errors]
        ) from None
    errors: list[str] = []

    def fail(key: str, message: str) -> None:
        errors.append(f"{path}: {key}: {message}")

    for key in raw:
        if key not in CAMPAIGN_KEYS:
            fail(str(key), f"unknown key (known: {', '.join(CAMPAIGN_KEYS)})")
    base, base_path = None, path
    source = raw.get("config")
    if source is None:
        fail("config", "missing: a config file (relative to this file) or a config inline")
    elif isinstance(source, str):
        base_path = (path.parent / source).resolve()
        try:
            base = read_yaml(base_path)
        except ConfigErrors as e:
            fail("config", "; ".join(e.errors))
    elif isinstance(source, dict):
        base = copy.deepcopy(source)
    else:
        fail("config", f"expected a file name or a config mapping, got {source!r}")
    if base is not None:
        base = absolute_paths(base, base_path.parent)

    def integer(key: str, default: int | None, minimum: int) -> int | None:
        value = raw.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            fail(key, f"expected a whole number >= {minimum}, got {value!r}")
            return None
        return value

    grid: dict[str, list] = {}
    raw_grid = raw.get("grid") or {}
    if not isinstance(raw_grid, dict):
        fail("grid", f"expected KEY: [values] pairs, got {raw_grid!r}")
        raw_grid = {}
    for key, values in raw_grid.items():
        if not isinstance(values, list) or not values:
            fail(f"grid.{key}", f"expected a non-empty list of values, got {values!r}")
        else:
            grid[str(key)] = values
    dispersions: list[Dispersion] = []
    raw_disperse = raw.get("disperse") or {}
    if not isinstance(raw_disperse, dict):
        fail("disperse", f"expected KEY: {{distribution: [...]}} pairs, got {raw_disperse!r}")
        raw_disperse = {}
    for key, spec in raw_disperse.items():
        if str(key) in grid:
            fail(f"disperse.{key}", "also in grid: a key is either on the grid or dispersed")
            continue
        try:
            dispersions.append(dispersion(str(key), spec, f"disperse.{key}"))
        except ConfigError as e:
            fail(e.key, e.message)
    samples = integer("samples", 1, 1)
    seed = integer("seed", 0, 0)
    if "samples" in raw and not dispersions and samples and samples > 1:
        fail("samples", "samples > 1 repeat draws of disperse:, and there is none (the cases would be identical)")
    if dispersions and "seed" not in raw:
        fail("seed", "missing: disperse needs a seed (every case's draws come from it and the case's index)")
    outcomes: dict[str, str] = {}
    raw_outcomes = raw.get("outcomes") or {}
    if not isinstance(raw_outcomes, dict):
        fail("outcomes", f"expected OUTCOME: EVENT pairs (e.g. captured: capture), got {raw_outcomes!r}")
        raw_outcomes = {}
    for name, event in raw_outcomes.items():
        if str(name) in RESERVED_OUTCOMES:
            fail(
                f"outcomes.{name}",
                f"{', '.join(RESERVED_OUTCOMES)} are the outcomes of a run itself: give another name",
            )
        elif not isinstance(event, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", event):
            fail(f"outcomes.{name}", f"expected an event name (e.g. capture), got {event!r}")
        elif event in outcomes.values():
            fail(
                f"outcomes.{name}",
                f"event {event!r} already makes outcome {next(k for k, v in outcomes.items() if v == event)!r}",
            )
        else:
            outcomes[str(name)] = event
    keep = raw.get("keep", "failed")
    if keep not in KEEP:
        fail("keep", f"expected one of {', '.join(KEEP)}, got {keep!r}")
    bad_keys = False
    for key in list(grid) + [d.key for d in dispersions]:
        where = f"grid.{key}" if key in grid else f"disperse.{key}"
        try:
            key_path(key)
        except ValueError as e:
            fail(where, str(e))
            bad_keys = True
            continue
        if base is not None:
            try:
                set_key(copy.deepcopy(base), key, 0)
            except ValueError as e:
                fail(where, str(e))
                bad_keys = True
    raw_metrics = raw.get("metrics") or {}
    if not isinstance(raw_metrics, dict):
        fail("metrics", f"expected NAME: {{signal, reduce}} pairs, got {raw_metrics!r}")
        raw_metrics = {}
    campaign = None
    signals = None
    if base is not None and not bad_keys:  # the cases and metrics are checked even when other keys are wrong
        campaign = Campaign(
            path=path,
            base=base,
            base_path=base_path,
            grid=grid,
            dispersions=dispersions,
            samples=samples or 1,
            seed=seed or 0,
            metrics=[],
            keep=keep,
            raw=raw,
            outcomes=outcomes,
        )
        indexes = range(campaign.count) if check_cases is True else (check_cases or [])
        seen: dict[str, list[int]] = {}  # a config key's problem: reported for its first case, counted after
        for index in indexes:
            if not 0 <= index < campaign.count:
                errors.append(f"{path}: --only {index}: the campaign has cases 0..{campaign.count - 1}")
                continue
            case = campaign.case(index)
            try:
                config = validate(case.raw, base_path)
            except ConfigErrors as e:
                for message in e.errors:
                    text = _config_problem(message)
                    key = text.split(": ", 1)[0]
                    if key in seen:
                        seen[key].append(index)
                        continue
                    seen[key] = [index]
                    errors.append(f"{path}: case {index} ({_describe(case.params)}): {text}")
                continue
            if signals is None:
                signals = signals_of(config)
        for key, cases in seen.items():
            if len(cases) > 1:
                listed = ", ".join(map(str, cases[1:6])) + (", ..." if len(cases) > 6 else "")
                errors.append(f"{path}: {key}: the same problem in {len(cases) - 1} more case(s) ({listed})")
    if base is not None and signals is None:  # the metrics are checked against the base config then
        try:
            signals = signals_of(validate(copy.deepcopy(base), base_path))
        except ConfigErrors:
            pass
    names = set()
    for name, spec in raw_metrics.items():
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\-]*", str(name)):
            fail(f"metrics.{name}", "a metric's name is letters, digits, '_', '-' or '.'")
            continue
        if (
            str(name) in ("case", "status", "outcome", "error", "wall_time", "attempts", "host", "recording")
            or str(name) in grid
            or str(name) in raw_disperse
        ):
            fail(f"metrics.{name}", "the name of a column cases.parquet has already: give another")
            continue
        try:
            parsed = metric(str(name), spec, signals, f"metrics.{name}")
        except ConfigError as e:
            fail(e.key, e.message)
            continue
        names.add(name)
        if campaign is not None:
            campaign.metrics.append(parsed)
    if errors:
        raise CampaignErrors(errors)
    return campaign


def _describe(params: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in params.items()) or "the base config"


def _config_problem(message: str) -> str:
    """A config error without the file name the config validation puts first (``FILE: key: message``)."""
    head, sep, rest = message.partition(": ")
    return rest if sep and (head.endswith((".yaml", ".yml")) or "/" in head) else message


def case_yaml(case: Case, campaign: Campaign) -> str:
    """The case's config as a YAML file (it runs by itself: ``orchestrator run`` it)."""
    head = (
        f"# case {case.index} of the campaign {campaign.path}\n"
        + "".join(f"#   {k}: {json.dumps(v, default=str)}\n" for k, v in case.params.items())
        + "# relative paths of the base config are made absolute\n"
    )
    return head + yaml.safe_dump(case.raw, sort_keys=False, default_flow_style=None, width=120)
