"""Load, override and validate a run config (docs/design.md §4) into typed structures.

Every problem is collected and reported at once, each naming its key and file; nothing is
started before the whole config is valid. Unknown keys are errors, as are missing required ones.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from components.constants import NS_PER_S
from components.schema import implausible_values
from components.sdk import RunSettings
from components.units import duration_text
from orchestrator.config import groups, timeline
from orchestrator.config.component_specs import component_specs, preflight_notes
from orchestrator.config.connections import parse_connections
from orchestrator.config.outcomes import expect_problem
from orchestrator.config.scene import fill_scenes
from orchestrator.config.schema import BUS, COMPONENT, CONFIG, FAULT, MAX_STEPS, ROS2, RUN, VIEWER
from orchestrator.config.shadows import mismatches, with_shadows
from orchestrator.config.specs import ComponentSpec, Event, Fault, Ros2Spec, RunConfig, ViewerSpec
from orchestrator.config.views import live_views
from orchestrator.config.yaml_file import ConfigErrors, apply_overrides, read_yaml
from orchestrator.hosts import bus_config


def load(path: str | Path, overrides: Sequence[str] = (), full: bool = False, strict: bool = False) -> RunConfig:
    """Read, override and validate ``path``; raises ConfigErrors listing every problem. ``full``
    (``orchestrator check``): the components also load what they would at the start (URDFs into
    DART), so that what fails there fails here. ``strict`` (``--strict``): warnings are errors."""
    path = Path(path)
    raw = read_yaml(path)
    apply_overrides(raw, list(overrides))
    return validate(raw, path, full, strict)


def validate(raw: dict, path: Path, full: bool = False, strict: bool = False) -> RunConfig:
    """The config checked against CONFIG, then across its parts (components, connections, events).
    Its warnings (values outside their plausible range, suspect physics) are ``notes``; with
    ``strict`` (``--strict``) or ``run.strict: true`` they are errors."""
    file = path
    with implausible_values() as found:
        config, problems = CONFIG.resolve(raw)
    errors = [f"{file}: {e.key}: {e.message}" for e in problems]
    run = config.get("run", {})
    step_ns, total_ns, epoch = run.get("step"), run.get("duration"), run.get("epoch")
    errors += _duration_problems(step_ns, total_ns, raw, file)
    config_dir = path.parent.resolve()
    packages = _packages(run.get("packages") or {}, config_dir, file, errors)
    fill_scenes(config, config_dir, file, errors)
    settings = RunSettings(epoch, config_dir, packages)
    components, shadows = component_specs(config.get("components", {}), step_ns, settings, file, errors)
    notes = [f"{file}: {f}" for f in found] + preflight_notes(
        [*components.values(), *shadows.values()], full, file, errors
    )
    connections = _connections(raw, config, components, shadows, file, errors)
    components, connections = with_shadows(components, shadows, connections)
    events, faults = _timeline(config, components, connections, step_ns, total_ns, settings, file, errors, notes)
    checkpoint_ns = run.get("checkpoint_every")
    errors += [f"{file}: {p}" for p in _run_problems(run, components, connections, checkpoint_ns)]
    bus_spec = _bus(config, config_dir, file, errors, notes)
    viewer, ros2 = live_views(config, path, components, errors)
    if not errors and notes and (strict or run["strict"]):
        errors = _strict_errors(notes, "--strict" if strict else "run.strict: true", file)
    if errors:
        raise ConfigErrors(errors)
    return RunConfig(
        path=path,
        name=run["name"],
        epoch=epoch,
        duration_ns=total_ns,
        step_ns=step_ns,
        algorithm=run["algorithm"],
        realtime=run["realtime"],
        step_timeout_s=run["step_timeout"] / NS_PER_S,
        start_timeout_s=run["start_timeout"] / NS_PER_S,
        components=components,
        connections=connections,
        listen=config["bus"]["listen"],
        bus=bus_spec,
        join_timeout_s=run["join_timeout"] / NS_PER_S,
        events=events,
        faults=faults,
        checkpoint_ns=checkpoint_ns,
        max_restarts=run["max_restarts"],
        viewer=viewer,
        ros2=ros2,
        resolved=_resolved_config(config, components, shadows, connections, events, faults, viewer, ros2),
        packages=packages,
        notes=notes,
        record_flush_s=run["record_flush"] / NS_PER_S,
        expect=run.get("expect"),
    )


def _connections(
    raw: dict,
    config: dict,
    components: dict[str, ComponentSpec],
    shadows: dict[str, ComponentSpec],
    file: Path,
    errors: list[str],
) -> list:
    """The connections, checked with the shadows' (each reads what its main reads) and the process
    groups'."""
    entries = raw.get("components")
    raw_entries = entries if isinstance(entries, dict) else {}
    connections = parse_connections(config.get("connections", {}), components, raw_entries, file, errors)
    for name, shadow in shadows.items():
        errors += [f"{file}: {shadow.key}: {p}" for p in mismatches(components[name], shadow, connections)]
    errors += [f"{file}: {p}" for p in groups.problems(list(components.values()))]
    return connections


def _timeline(
    config: dict,
    components: dict[str, ComponentSpec],
    connections: list,
    step_ns: int | None,
    total_ns: int | None,
    settings: RunSettings,
    file: Path,
    errors: list[str],
    notes: list[str],
) -> tuple[list[Event], list[Fault]]:
    """The events and the faults; the events' new generations' warnings go to ``notes``."""
    events = timeline.swap_events(
        config.get("events", []), components, connections, step_ns, total_ns, settings, file, errors
    )
    faults = timeline.faults(config.get("faults", []), components, total_ns, file, errors)
    notes += [f"{file}: {line}" for event in events for line in event.spec.implausible]
    return events, faults


def _run_problems(run: dict, components: dict[str, ComponentSpec], connections: list, checkpoint_ns) -> list[str]:
    """What the run: section asks that the components cannot give: restarts, the expected outcome."""
    problems = _restart_problems(components, connections, checkpoint_ns)
    if run.get("expect") is not None and (problem := expect_problem(components, run["expect"])):
        problems.append(f"run.expect: {problem}")
    return problems


def _bus(config: dict, config_dir: Path, file: Path, errors: list[str], notes: list[str]):
    """The bus: section checked (None without one); plain TCP beyond loopback is a warning."""
    bus_spec = bus_config.check(config["bus"], config_dir, errors, file) if "bus" in config else None
    if bus_spec is not None and bus_spec.plaintext_beyond:
        notes.append(
            f"{file}: bus: plain TCP beyond loopback ({', '.join(bus_spec.plaintext_beyond)}), as "
            f"bus.plaintext: accept-the-risk allows: anyone on those networks can read the run's traffic"
        )
    return bus_spec


def _strict_errors(notes: list[str], why: str, file: Path) -> list[str]:
    """The warnings as errors (``why``: --strict or run.strict), and a line saying so."""
    return notes + [
        f"{file}: {why} makes the warning above an error"
        if len(notes) == 1
        else f"{file}: {why} makes the {len(notes)} warnings above errors"
    ]


def _duration_problems(step_ns: int | None, total_ns: int | None, raw: dict, file: Path) -> list[str]:
    """run.duration a whole number of steps, and not more of them than an experiment takes."""
    if not (step_ns and total_ns):
        return []
    if total_ns % step_ns:
        return [
            f"{file}: run.duration: must be a whole number of steps of {duration_text(step_ns)}, "
            f"got {raw['run']['duration']!r}"
        ]
    if total_ns // step_ns > MAX_STEPS:
        return [
            f"{file}: run.duration: {total_ns // step_ns:.3g} steps of {duration_text(step_ns)}; at most "
            f"{MAX_STEPS:.0e} steps (at a million steps per second, 11 days of wall time)"
        ]
    return []


def _packages(given: dict, config_dir: Path, file: Path, errors: list[str]) -> dict[str, str]:
    """run.packages as absolute directories; one not found is an error."""
    packages = {}
    for package, directory in given.items():
        where = (config_dir / directory).resolve()
        if not where.is_dir():
            errors.append(f"{file}: run.packages.{package}: directory {directory!r} not found ({where})")
        packages[package] = str(where)
    return packages


def _restart_problems(components: dict[str, ComponentSpec], connections: list, checkpoint_ns: int | None) -> list[str]:
    """What a restart from a checkpoint needs: frames aside, every component's state, and
    checkpoints on every component's step boundary."""
    restarting = [n for n, spec in components.items() if spec.on_failure == "restart"]
    problems = frame_problems(components, connections, restarting)
    for name, spec in components.items():
        problem = spec.cls.state_problem(spec.typed, spec.run) if restarting else None
        if problem:
            problems.append(
                f"components.{restarting[0]}.on_failure: restart needs the state of every "
                f"component, and {name} ({spec.type}) cannot give it: {problem}"
            )
    if checkpoint_ns is not None:
        problems += [
            f"run.checkpoint_every: must be a multiple of every component's step "
            f"(all are at a step boundary then); {name} steps {duration_text(spec.step_ns)}, "
            f"got {duration_text(checkpoint_ns)}"
            for name, spec in components.items()
            if checkpoint_ns % spec.step_ns
        ]
    return problems


def _resolved_config(
    config: dict,
    components: dict[str, ComponentSpec],
    shadows: dict[str, ComponentSpec],
    connections: list,
    events: list[Event],
    faults: list[Fault],
    viewer: ViewerSpec | None,
    ros2: Ros2Spec | None,
) -> dict:
    """The config as config.yaml records it: every default filled in, in the config's units."""
    resolved = {
        "run": RUN.plain(config["run"]),
        "bus": BUS.plain(config["bus"]),
        "components": {n: _resolved_entry(s, shadows.get(n)) for n, s in components.items() if not s.shadow_of},
        "connections": {f"{d}.{dv}": f"{s}.{sv}" for d, dv, s, sv in connections if not components[d].shadow_of},
        "events": [
            {
                "at": duration_text(e.at_ns),
                "swap": e.swap,
                "type": e.type,
                "parameters": e.spec.cls.schema.plain(e.spec.resolved),
            }
            for e in events
        ],
        "faults": [
            FAULT.plain({"at": f.at_ns, "component": f.component, "kind": f.kind, "duration": f.duration_ns})
            for f in faults
        ],
    }
    if viewer is not None:
        resolved["viewer"] = VIEWER.plain(config["viewer"])
    if ros2 is not None:
        resolved["ros2"] = ROS2.plain({**config["ros2"], "domain_id": ros2.domain_id})
    return resolved


def _resolved_entry(spec: ComponentSpec, shadow: ComponentSpec | None) -> dict:
    """A component's entry in the resolved config.yaml, its shadow nested in it."""
    entry = {
        **COMPONENT.plain(
            {
                "type": spec.type,
                "step": spec.step_ns,
                "launch": spec.launch,
                "dedicated_cpu": spec.dedicated_cpu,
                "on_failure": spec.on_failure,
                "process": spec.process,
            }
        ),
        "parameters": spec.cls.schema.plain(spec.resolved),
    }
    del entry["shadow"]
    if spec.process is None:  # one process per component: the default, unwritten
        del entry["process"]
    if shadow is not None:
        entry["shadow"] = {"type": shadow.type, "parameters": shadow.cls.schema.plain(shadow.resolved)}
    return entry


def frame_problems(components: dict[str, ComponentSpec], connections: list, restarting: list[str]) -> list[str]:
    """What a run with frame connections cannot do yet (docs/component_api.md, "Images in a step"):
    a frame is part of no state and is not sent again to a new generation, so a restart would
    wait for a frame that never comes (a swap: :func:`check_replacement`)."""
    frames = [(d, dv, s, sv) for d, dv, s, sv in connections if components[d].variables[dv].frame]
    framed = {n for d, _, s, _ in frames for n in (d, s)}
    problems = [
        f"connections.{d}.{dv}: a component cannot read its own frames (from {s}.{sv})"
        for d, dv, s, sv in frames
        if d == s
    ]
    return problems + [
        f"components.{n}.on_failure: restart is not supported yet in a run with frame connections "
        f"({', '.join(sorted(framed))} exchange images)"
        for n in restarting[:1]
        if framed
    ]
