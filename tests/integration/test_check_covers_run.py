"""`check` finds every parameter error `run` would (issue 34). For every component of every shipped
config, each declared parameter whose kind tells a value it refuses (below a minimum, zero where
positive, above a maximum, a word not among its choices, a vector one element too long, a
duration that is not a whole number of the component's steps, an empty list that needs items) is
given that value, one at a time:

- `check` (the config loaded in full, as `orchestrator check` does) refuses it naming the key, or
- the run, stepped in this process (instantiate, initialize, first step: where components make
  their own checks), must accept it too: a run refusing what check let through fails the test.

Today check refuses all 126 of them; before the relative-pose sensor's latency was checked there,
its 1.5-step latency passed check and failed the run at step 0.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from components.constants import NS_PER_S
from components.errors import ComponentError, ConfigError
from components.schema import Bool, Duration, Float, Int, ListOf, Str, Vector
from orchestrator.config.load import load
from orchestrator.config.yaml_file import ConfigErrors
from orchestrator.run.inprocess import run_in_process
from tests.conftest import SHIPPED, config_missing


def refused_value(kind, step_ns: int):
    """A value the kind itself refuses, or that a component's step makes wrong; None if none."""
    if isinstance(kind, Float):
        if kind.positive:
            return 0.0
        if kind.minimum is not None:
            return kind.minimum - 1.0
        if kind.maximum is not None:
            return kind.maximum + 1.0
    if isinstance(kind, Int) and kind.minimum is not None:
        return kind.minimum - 1
    if isinstance(kind, Str) and kind.choices:
        return "no-such-choice"
    if isinstance(kind, Bool):
        return "maybe"
    if isinstance(kind, Vector) and kind.size is not None:
        return [0.0] * (kind.size + 1)
    if isinstance(kind, Duration):
        return f"{step_ns * 1.5 / NS_PER_S!r} s"  # not a whole number of steps
    if isinstance(kind, ListOf) and kind.min_items:
        return []
    return None


def cases():
    for config in SHIPPED:
        if why := config_missing(config):
            yield pytest.param(config, None, None, None, id=config.stem, marks=pytest.mark.skip(reason=why))
            continue
        base = load(config)
        for name, spec in base.components.items():
            for parameter in spec.cls.parameters:
                value = refused_value(parameter.kind, spec.step_ns)
                if value is not None:
                    yield pytest.param(config, name, parameter.name, value, id=f"{config.stem}-{name}-{parameter.name}")


@pytest.mark.parametrize("config, component, parameter, value", list(cases()))
def test_what_check_accepts_the_run_accepts(config: Path, component: str, parameter: str, value):
    override = f"components.{component}.parameters.{parameter}={yaml.safe_dump(value, default_flow_style=True).strip()}"
    if override.endswith("\n..."):
        override = override[:-4]
    try:
        checked = load(config, [override], full=True)
    except ConfigErrors as e:
        key = f"components.{component}.parameters.{parameter}"
        assert any(key in line for line in e.errors), (override, e.errors)
        return
    try:
        run_in_process(checked, steps=1)
    except (ConfigError, ComponentError, ValueError) as e:
        pytest.fail(f"check accepted {override} but the run refused it: {type(e).__name__}: {e}")
