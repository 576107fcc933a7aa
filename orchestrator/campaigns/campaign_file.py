"""A campaign file read and validated (``load_campaign``): its own keys, then every case's config
against the config schema, then its metrics against the signals a case records. Every problem
is collected, each naming its key, and raised together as CampaignErrors."""

from __future__ import annotations

import copy
import re
from pathlib import Path
from typing import Any

from components.errors import ConfigError
from orchestrator.campaigns.campaign import Campaign, key_path, set_key
from orchestrator.campaigns.dispersions import Dispersion, dispersion
from orchestrator.campaigns.metrics import Metric, metric, signals_of
from orchestrator.config.load import validate
from orchestrator.config.yaml_file import ConfigErrors, read_yaml

CAMPAIGN_KEYS = ("config", "grid", "disperse", "samples", "seed", "metrics", "outcomes", "keep")
RESERVED_OUTCOMES = ("completed", "failed", "interrupted")
KEEP = ("all", "failed", "none")
# the columns cases.parquet has besides the keys and the metrics
CASE_COLUMNS = ("case", "status", "outcome", "error", "wall_time", "attempts", "host", "recording")


class CampaignErrors(Exception):
    """Every problem of a campaign file, each ``file: key: message``."""

    def __init__(self, errors: list[str]):
        super().__init__("\n".join(errors))
        self.errors = errors


class _Problems:
    """The problems found so far, in the order they are found, each naming the campaign file."""

    def __init__(self, path: Path):
        self.path = path
        self.errors: list[str] = []

    def fail(self, key: str, message: str) -> None:
        self.errors.append(f"{self.path}: {key}: {message}")

    def add(self, text: str) -> None:
        self.errors.append(f"{self.path}: {text}")


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
    problems = _Problems(path)
    fail = problems.fail
    for key in raw:
        if key not in CAMPAIGN_KEYS:
            fail(str(key), f"unknown key (known: {', '.join(CAMPAIGN_KEYS)})")
    base, base_path = _base(raw, path, fail)
    grid = _grid(raw, fail)
    dispersions, raw_disperse = _dispersions(raw, grid, fail)
    samples = _integer(raw, "samples", 1, 1, fail)
    seed = _integer(raw, "seed", 0, 0, fail)
    if "samples" in raw and not dispersions and samples and samples > 1:
        fail("samples", "samples > 1 repeat draws of disperse:, and there is none (the cases would be identical)")
    if dispersions and "seed" not in raw:
        fail("seed", "missing: disperse needs a seed (every case's draws come from it and the case's index)")
    outcomes = _outcomes(raw, fail)
    keep = raw.get("keep", "failed")
    if keep not in KEEP:
        fail("keep", f"expected one of {', '.join(KEEP)}, got {keep!r}")
    bad_keys = _bad_keys(grid, dispersions, base, fail)
    raw_metrics = _section(raw, "metrics", "NAME: {signal, reduce} pairs", fail)
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
        signals = _check_cases(campaign, check_cases, problems)
    if base is not None and signals is None:  # the metrics are checked against the base config then
        try:
            signals = signals_of(validate(copy.deepcopy(base), base_path))
        except ConfigErrors:
            pass
    metrics = _metrics(raw_metrics, signals, [*grid, *raw_disperse], fail)
    if campaign is not None:
        campaign.metrics.extend(metrics)
    if problems.errors:
        raise CampaignErrors(problems.errors)
    assert campaign is not None  # no base config, or a bad key, is a problem
    return campaign


def _section(raw: dict, key: str, expected: str, fail) -> dict:
    """The campaign's mapping ``key`` ({} if it is none or not a mapping: a problem then)."""
    section = raw.get(key) or {}
    if not isinstance(section, dict):
        fail(key, f"expected {expected}, got {section!r}")
        return {}
    return section


def _base(raw: dict, path: Path, fail) -> tuple[dict | None, Path]:
    """The base config (its relative paths made absolute, None if it cannot be read) and the path
    its relative paths were relative to."""
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
    return base, base_path


def _integer(raw: dict, key: str, default: int | None, minimum: int, fail) -> int | None:
    value = raw.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        fail(key, f"expected a whole number >= {minimum}, got {value!r}")
        return None
    return value


def _grid(raw: dict, fail) -> dict[str, list]:
    grid: dict[str, list] = {}
    for key, values in _section(raw, "grid", "KEY: [values] pairs", fail).items():
        if not isinstance(values, list) or not values:
            fail(f"grid.{key}", f"expected a non-empty list of values, got {values!r}")
        else:
            grid[str(key)] = values
    return grid


def _dispersions(raw: dict, grid: dict[str, list], fail) -> tuple[list[Dispersion], dict]:
    """The dispersions, and the disperse: section as given (its keys name no metric)."""
    dispersions: list[Dispersion] = []
    raw_disperse = _section(raw, "disperse", "KEY: {distribution: [...]} pairs", fail)
    for key, spec in raw_disperse.items():
        if str(key) in grid:
            fail(f"disperse.{key}", "also in grid: a key is either on the grid or dispersed")
            continue
        try:
            dispersions.append(dispersion(str(key), spec, f"disperse.{key}"))
        except ConfigError as e:
            fail(e.key, e.message)
    return dispersions, raw_disperse


def _outcomes(raw: dict, fail) -> dict[str, str]:
    """Outcome name -> the event that makes it."""
    outcomes: dict[str, str] = {}
    for name, event in _section(raw, "outcomes", "OUTCOME: EVENT pairs (e.g. captured: capture)", fail).items():
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
    return outcomes


def _bad_keys(grid: dict[str, list], dispersions: list[Dispersion], base: dict | None, fail) -> bool:
    """Whether a grid or dispersed key is malformed or leads nowhere in the base config."""
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
    return bad_keys


def _check_cases(campaign: Campaign, check_cases: bool | list[int], problems: _Problems) -> dict | None:
    """Each case's config validated (a config key's problem reported for its first case, the others
    counted); the signals of the first valid one, for the metrics, or None."""
    signals = None
    count = campaign.count
    indexes = range(count) if check_cases is True else (check_cases or [])
    seen: dict[str, list[int]] = {}
    for index in indexes:
        if not 0 <= index < count:
            problems.add(f"--only {index}: the campaign has cases 0..{count - 1}")
            continue
        case = campaign.case(index)
        try:
            config = validate(case.raw, campaign.base_path)
        except ConfigErrors as e:
            for message in e.errors:
                text = _config_problem(message)
                key = text.split(": ", 1)[0]
                if key in seen:
                    seen[key].append(index)
                    continue
                seen[key] = [index]
                problems.add(f"case {index} ({_describe(case.params)}): {text}")
            continue
        if signals is None:
            signals = signals_of(config)
    for key, cases in seen.items():
        if len(cases) > 1:
            listed = ", ".join(map(str, cases[1:6])) + (", ..." if len(cases) > 6 else "")
            problems.add(f"{key}: the same problem in {len(cases) - 1} more case(s) ({listed})")
    return signals


def _metrics(raw_metrics: dict, signals, taken: list[str], fail) -> list[Metric]:
    """The metrics parsed against the case's ``signals``; ``taken``: the grid's and dispersed keys,
    columns of cases.parquet like CASE_COLUMNS."""
    metrics = []
    for name, spec in raw_metrics.items():
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\-]*", str(name)):
            fail(f"metrics.{name}", "a metric's name is letters, digits, '_', '-' or '.'")
            continue
        if str(name) in CASE_COLUMNS or str(name) in taken:
            fail(f"metrics.{name}", "the name of a column cases.parquet has already: give another")
            continue
        try:
            metrics.append(metric(str(name), spec, signals, f"metrics.{name}"))
        except ConfigError as e:
            fail(e.key, e.message)
    return metrics


def _describe(params: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in params.items()) or "the base config"


def _config_problem(message: str) -> str:
    """A config error without the file name the config validation puts first (``FILE: key: message``)."""
    head, sep, rest = message.partition(": ")
    return rest if sep and (head.endswith((".yaml", ".yml")) or "/" in head) else message
