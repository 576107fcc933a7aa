"""Each component's spec from its config entry: its type loaded, its parameters resolved against
the run (units, defaults, files), its variables declared; its shadow's too; and the types'
preflight warnings. Every problem is reported as ConfigErrors naming its key."""

from __future__ import annotations

from pathlib import Path
from typing import cast

from components import registry
from components.constants import NS_PER_S
from components.errors import ConfigError
from components.schema import implausible_values
from components.sdk import RunSettings
from components.units import duration_text
from orchestrator.config.shadows import shadow_spec
from orchestrator.config.specs import ComponentSpec
from orchestrator.config.yaml_file import ConfigErrors


def component_spec(name: str, entry: dict, run_step_ns: int, run: RunSettings, key: str) -> ComponentSpec:
    """One component's spec from its entry as COMPONENT converts it; ConfigErrors naming ``key.<...>``."""
    errors: list[str] = []
    type_name = entry["type"]
    try:
        cls = registry.load(type_name, run.config_dir)
    except ConfigError as e:
        raise ConfigErrors([f"{key}.type: {e.message}"]) from None
    step_ns = run_step_ns if entry["step"] is None else entry["step"]
    if step_ns % run_step_ns:
        errors.append(
            f"{key}.step: must be a positive integer multiple of run.step "
            f"({duration_text(run_step_ns)}), got {duration_text(step_ns)}"
        )
    params_raw = entry["parameters"]
    if not isinstance(params_raw, dict):
        raise ConfigErrors([f"{key}.parameters: expected a mapping, got {params_raw!r}"])
    unresolved = None
    try:
        with implausible_values() as found:
            resolved = registry.resolve(cls, params_raw, run)
    except registry.Unresolved as e:
        unresolved = e
    if unresolved and unresolved.stage == "parameters":
        errors += [
            f"{key}.parameters.{e.key}: {e.message}" if e.key else f"{key}.parameters: {e.message}"
            for e in cast("list[ConfigError]", unresolved.errors)  # the parameters stage raises ConfigErrors
        ]
    if entry["dedicated_cpu"] and entry["launch"] == "external":
        errors.append(
            f"{key}.dedicated_cpu: only for components the orchestrator starts (launch: local); "
            f"pin an external component where it runs (taskset)"
        )
    if errors:
        raise ConfigErrors(errors)
    if unresolved:  # declare failed; a component's own bug or a file it cannot read is one line too
        raise ConfigErrors([_declare_failure(unresolved.errors[0], key, type_name)])
    return ComponentSpec(
        name=name,
        type=type_name,
        cls=cls,
        step_ns=step_ns,
        parameters=params_raw,
        resolved=resolved.params,
        typed=resolved.typed,
        run=run,
        launch=entry["launch"],
        dedicated_cpu=entry["dedicated_cpu"],
        on_failure=entry["on_failure"],
        process=entry["process"],
        inputs=resolved.inputs,
        outputs=resolved.outputs,
        implausible=[f"{key}.parameters.{f}" for f in found],
    )


def _declare_failure(e: Exception, key: str, type_name: str) -> str:
    """Why a type could not declare its variables: a parameter's problem, or its own error."""
    if isinstance(e, ConfigError):
        return f"{key}.parameters.{e.key}: {e.message}"
    return f"{key}.parameters: {type_name} cannot declare its variables: {type(e).__name__}: {e}"


def component_specs(
    entries: dict, step_ns: int | None, run: RunSettings, file: Path, errors: list[str]
) -> tuple[dict[str, ComponentSpec], dict[str, ComponentSpec]]:
    """The components' specs and their shadows' (main's name -> its shadow); none without a step
    and an epoch (their errors are said already)."""
    components: dict[str, ComponentSpec] = {}
    shadows: dict[str, ComponentSpec] = {}
    if step_ns is None or run.epoch is None:
        return components, shadows
    for name, entry in entries.items():
        try:
            components[name] = component_spec(name, entry, step_ns, run, f"components.{name}")
            if entry["shadow"] is not None:
                shadows[name] = shadow_spec(
                    components[name],
                    entry["shadow"],
                    entries,
                    lambda n, e, key: component_spec(n, e, step_ns, run, key),
                )
        except ConfigErrors as e:
            errors += [f"{file}: {m}" for m in e.errors]
    return components, shadows


def preflight_notes(specs: list[ComponentSpec], full: bool, file: Path, errors: list[str]) -> list[str]:
    """Each spec's implausible values and its type's preflight warnings; a preflight that fails is an error."""
    notes = [f"{file}: {line}" for spec in specs for line in spec.implausible]
    for spec in specs:
        key = f"{spec.key}.parameters"
        try:
            notes += [
                f"{file}: {key}.{note}"
                for note in spec.cls.preflight(spec.typed, spec.run, spec.step_ns / NS_PER_S, full)
            ]
        except ConfigError as e:
            errors.append(f"{file}: {key}.{e.key}: {e.message}" if e.key else f"{file}: {key}: {e.message}")
        except Exception as e:  # a component's own check failing is a line too, not a traceback
            errors.append(f"{file}: {key}: {spec.type} cannot load its model: {type(e).__name__}: {e}")
    return notes
