"""The config's timeline: its events (a component swapped at a time, to a new generation of its
own or another type) and its faults (injected into a component at a time), each checked against
the components and connections; problems go to ``errors``, each naming its key and file."""

from __future__ import annotations

from pathlib import Path

from components import registry
from components.errors import ConfigError
from components.sdk import RunSettings
from components.units import duration_text
from orchestrator.config.component_specs import component_spec
from orchestrator.config.connections import check_replacement, handover_problem, hands_over
from orchestrator.config.shadows import mismatches
from orchestrator.config.specs import ComponentSpec, Event, Fault
from orchestrator.config.yaml_file import ConfigErrors


def swap_events(
    entries: list[dict],
    components: dict[str, ComponentSpec],
    connections: list,
    step_ns: int | None,
    total_ns: int | None,
    run: RunSettings,
    file: Path,
    errors: list[str],
) -> list[Event]:
    """The events in time order; an event with a problem is left out (its first problem said)."""
    events = []
    for i, entry in enumerate(entries):
        try:
            events.append(_swap_event(f"events[{i}]", entry, components, connections, step_ns, total_ns, run))
        except ConfigErrors as e:
            errors += [f"{file}: {m}" for m in e.errors]
    return sorted(events, key=lambda e: e.at_ns)


def _swap_event(
    key: str,
    entry: dict,
    components: dict[str, ComponentSpec],
    connections: list,
    step_ns: int | None,
    total_ns: int | None,
    run: RunSettings,
) -> Event:
    """One event: its new generation's spec, checked against the one it replaces; ConfigErrors."""
    target = entry["swap"]
    old = components.get(target)
    if old is None:
        raise ConfigErrors([f"{key}.swap: no component named {target!r}"])
    assert step_ns is not None, "a config without run.step has no components"
    new_type, handed_over = _swap_type(key, entry, old, total_ns, run)
    params = entry["parameters"]
    if params is None:
        params = old.parameters if handed_over else {}
    spec = component_spec(
        target,
        {
            "type": new_type,
            "parameters": params,
            "step": old.step_ns,
            "launch": "local",
            "dedicated_cpu": False,
            "on_failure": old.on_failure,
            "process": None,
        },  # a new generation runs in a process of its own
        step_ns,
        run,
        key,
    )
    problem = handover_problem(old, spec) if handed_over else None
    if problem:
        raise ConfigErrors([f"{key}: {problem}"])
    spec.shadow_of = old.shadow_of
    problems = check_replacement(spec, connections) + (
        mismatches(components[old.shadow_of], spec, connections) if old.shadow_of else []
    )
    if problems:
        raise ConfigErrors([f"{key}: {p}" for p in problems])
    return Event(at_ns=entry["at"], swap=target, type=new_type, parameters=params, spec=spec)


def _swap_type(key: str, entry: dict, old: ComponentSpec, total_ns: int | None, run: RunSettings) -> tuple[str, bool]:
    """The event's time checked against the run and ``old``'s steps; the new type, and whether it
    takes ``old``'s state (which ``old`` must then be able to give); ConfigErrors."""
    at_ns = entry["at"]
    if total_ns is not None and at_ns >= total_ns:
        raise ConfigErrors([f"{key}.at: must be within the run, 0 <= at < run.duration, got {duration_text(at_ns)}"])
    if at_ns % old.step_ns:
        raise ConfigErrors(
            [
                f"{key}.at: must fall on a step boundary of {entry['swap']} "
                f"(a multiple of {duration_text(old.step_ns)}), got {duration_text(at_ns)}"
            ]
        )
    new_type = entry["type"] or old.type
    try:
        handed_over = hands_over(old, new_type, registry.load(new_type, run.config_dir))
    except ConfigError as e:
        raise ConfigErrors([f"{key}.type: {e.message}"]) from None
    problem = old.cls.state_problem(old.typed, old.run) if handed_over else None
    if problem:
        what = "the same type" if new_type == old.type else new_type
        raise ConfigErrors(
            [
                f"{key}.swap: a swap to {what} hands the state over, and {entry['swap']} "
                f"cannot: {problem} (give another type)"
            ]
        )
    return new_type, handed_over


def faults(
    entries: list[dict], components: dict[str, ComponentSpec], total_ns: int | None, file: Path, errors: list[str]
) -> list[Fault]:
    """The faults in time order; one with a problem is left out."""
    faults = []
    for i, entry in enumerate(entries):
        key = f"faults[{i}]"
        if entry["component"] not in components:
            errors.append(
                f"{file}: {key}.component: no component named {entry['component']!r} "
                f"(components: {', '.join(components)})"
            )
        elif total_ns is not None and entry["at"] >= total_ns:
            errors.append(
                f"{file}: {key}.at: must be within the run, 0 <= at < run.duration, got {duration_text(entry['at'])}"
            )
        elif entry["kind"] == "nan" and not components[entry["component"]].outputs.size:
            errors.append(f"{file}: {key}.kind: {entry['component']} has no output to make NaN")
        elif (entry["kind"] == "delay") != (entry["duration"] is not None):
            errors.append(
                f"{file}: {key}.duration: "
                + (
                    "a delay needs one (e.g. duration: 2 s)"
                    if entry["kind"] == "delay"
                    else f"only a delay has one, not a {entry['kind']}"
                )
            )
        else:
            faults.append(Fault(entry["at"], entry["component"], entry["kind"], entry["duration"]))
    return sorted(faults, key=lambda f: f.at_ns)
