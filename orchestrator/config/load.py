"""Load, override and validate a run config (docs/design.md §4) into typed structures.

Every problem is collected and reported at once, each naming its key and file; nothing is
started before the whole config is valid. Unknown keys are errors, as are missing required ones.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from components import registry
from components.constants import NS_PER_S
from components.errors import ConfigError
from components.extras import missing
from components.schema import implausible_values
from components.sdk import RunSettings
from components.units import duration_text
from orchestrator.config import groups
from orchestrator.config.connections import check_replacement, handover_problem, hands_over, parse_connections
from orchestrator.config.schema import BUS, COMPONENT, CONFIG, FAULT, MAX_STEPS, ROS2, RUN, VIEWER
from orchestrator.config.shadows import mismatches, shadow_spec, with_shadows
from orchestrator.config.specs import ComponentSpec, Event, Fault, Ros2Spec, RunConfig, ViewerSpec
from orchestrator.config.yaml_file import ConfigErrors, apply_overrides, read_yaml
from orchestrator.hosts import bus_config
from orchestrator.run.outcome import expect_problem


def viewer_spec(raw: Any, where: str, errors: list[str], base: Path) -> ViewerSpec | None:
    """Parse a ``viewer:`` section or a ``--view`` value (``spawn``, ``web``, ``save:FILE.rrd``,
    ``foxglove[:PORT]``)."""
    if isinstance(raw, str):
        mode, _, rest = raw.partition(":")
        if mode == "foxglove" and rest:
            if not rest.isdigit():
                errors.append(f"{where}: foxglove:PORT needs a port number, got {rest!r}")
                return None
            raw = {"mode": mode, "port": int(rest)}
        else:
            raw = {"mode": mode, **({"file": rest} if rest else {})}
    section, problems = VIEWER.resolve(raw, where)
    if problems:
        errors += [str(e) for e in problems]
        return None
    return _viewer(section, where, errors, base)


def _viewer(section: dict, where: str, errors: list[str], base: Path) -> ViewerSpec | None:
    if section["mode"] == "off":
        return None
    if section["mode"] == "save" and section["file"] is None:
        errors.append(f"{where}.file: save needs a file name ending in .rrd (e.g. save:run.rrd), got none")
        return None
    if section["mode"] != "foxglove" and (problem := missing("view", f"the Rerun viewer ({section['mode']})")):
        errors.append(f"{where}: {problem}")
        return None
    file = section["file"]
    if section["port"] > 65535:
        errors.append(f"{where}.port: expected a port number 1..65535, got {section['port']}")
        return None
    return ViewerSpec(
        mode=section["mode"],
        file=(base / file) if file else None,
        rate_hz=section["rate"],
        open_browser=section["open_browser"],
        port=section["port"],
    )


def clock_clash(components: dict[str, ComponentSpec], ros2: Ros2Spec | None, where: str) -> str | None:
    """Why the live ROS 2 view cannot publish ``/clock`` beside a ``ros2.bridge`` that does, in one
    domain, or None: a node with use_sim_time would hear two clocks, the view's lagging the bridge's."""
    if ros2 is None or (ros2.topics is not None and "/clock" not in ros2.topics):
        return None
    for name, spec in components.items():
        if spec.type == "ros2.bridge" and spec.resolved["clock"] and spec.resolved["domain_id"] == ros2.domain_id:
            return (
                f"{where}: the live ROS 2 view would publish /clock in domain {ros2.domain_id}, where the bridge "
                f"{name!r} publishes the run's /clock in lockstep (a node with use_sim_time would hear both): "
                f"give ros2.topics without /clock, or components.{name}.parameters.clock: false"
            )
    return None


def ros2_spec(raw: Any, where: str, errors: list[str], endpoint: str | None = None) -> Ros2Spec | None:
    """Parse a ``ros2:`` section (None: the defaults); ``endpoint``: ``--ros2 TRANSPORT|ENDPOINT``,
    which wins (an endpoint means transport zenoh). The domain id, if not given, is the
    environment's ROS_DOMAIN_ID, else 0. The transport is chosen here (auto: rclpy if a Python
    imports it). A topic name ROS 2 rejects, or rclpy asked for and not found: an error naming it."""
    import os

    from components.errors import ComponentError
    from components.ros2.rclpy_transport import TRANSPORTS, ZENOH, choose
    from components.ros2.rmw_zenoh import check_topic_name

    if raw is None or isinstance(raw, dict):
        if endpoint in TRANSPORTS:
            given = {"transport": endpoint}
        elif endpoint is not None:
            given = {"endpoint": endpoint, "transport": ZENOH}
        else:
            given = {}
        raw = {**(raw or {}), **given}
    section, problems = ROS2.resolve(raw, where)
    if problems:
        errors += [str(e) for e in problems]
        return None
    domain_id = section["domain_id"]
    if domain_id is None:
        text = os.environ.get("ROS_DOMAIN_ID", "").strip()
        if text and not text.isdigit():
            errors.append(f"{where}.domain_id: from ROS_DOMAIN_ID, expected an integer >= 0, got {text!r}")
            return None
        domain_id = int(text) if text else 0
    rejected = [
        f"{where}.topics[{i}]: ROS 2 rejects the topic name {topic!r}: {problem}"
        for i, topic in enumerate(section["topics"] or [])
        if (problem := check_topic_name(topic))
    ]
    if rejected:
        errors += rejected
        return None
    try:
        transport, python, why = choose(section["transport"], section["python"])
    except ComponentError as e:
        errors.append(f"{where}.transport: {e}")
        return None
    return Ros2Spec(
        endpoint=section["endpoint"],
        domain_id=domain_id,
        distro=section["distro"],
        topics=section["topics"],
        rate_hz=section["rate"],
        transport=transport,
        python=python,
        why=why,
    )


def load(path: str | Path, overrides: list[str] = (), full: bool = False, strict: bool = False) -> RunConfig:
    """Read, override and validate ``path``; raises ConfigErrors listing every problem. ``full``
    (``orchestrator check``): the components also load what they would at the start (URDFs into
    DART), so that what fails there fails here. ``strict`` (``--strict``): warnings are errors."""
    path = Path(path)
    raw = read_yaml(path)
    apply_overrides(raw, list(overrides))
    return validate(raw, path, full, strict)


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
            for e in unresolved.errors
        ]
    if entry["dedicated_cpu"] and entry["launch"] == "external":
        errors.append(
            f"{key}.dedicated_cpu: only for components the orchestrator starts (launch: local); "
            f"pin an external component where it runs (taskset)"
        )
    if errors:
        raise ConfigErrors(errors)
    if unresolved:  # declare failed; a component's own bug or a file it cannot read is one line too
        e = unresolved.errors[0]
        raise ConfigErrors(
            [
                f"{key}.parameters.{e.key}: {e.message}"
                if isinstance(e, ConfigError)
                else f"{key}.parameters: {type_name} cannot declare its variables: {type(e).__name__}: {e}"
            ]
        )
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
    if step_ns and total_ns and total_ns % step_ns:
        errors.append(
            f"{file}: run.duration: must be a whole number of steps of {duration_text(step_ns)}, "
            f"got {raw['run']['duration']!r}"
        )
    elif step_ns and total_ns and total_ns // step_ns > MAX_STEPS:
        errors.append(
            f"{file}: run.duration: {total_ns // step_ns:.3g} steps of {duration_text(step_ns)}; at most "
            f"{MAX_STEPS:.0e} steps (at a million steps per second, 11 days of wall time)"
        )
    components: dict[str, ComponentSpec] = {}
    config_dir = path.parent.resolve()
    packages = {}
    for package, directory in (run.get("packages") or {}).items():
        where = (config_dir / directory).resolve()
        if not where.is_dir():
            errors.append(f"{file}: run.packages.{package}: directory {directory!r} not found ({where})")
        packages[package] = str(where)
    entries = config.get("components", {})
    shadows: dict[str, ComponentSpec] = {}  # main's name -> its shadow
    settings = RunSettings(epoch, config_dir, packages)
    if step_ns is not None and epoch is not None:
        for name, entry in entries.items():
            try:
                components[name] = component_spec(name, entry, step_ns, settings, f"components.{name}")
                if entry["shadow"] is not None:
                    shadows[name] = shadow_spec(
                        components[name],
                        entry["shadow"],
                        entries,
                        lambda n, e, key: component_spec(n, e, step_ns, settings, key),
                    )
            except ConfigErrors as e:
                errors += [f"{file}: {m}" for m in e.errors]
    notes = [f"{file}: {f}" for f in found]
    notes += [f"{file}: {line}" for spec in [*components.values(), *shadows.values()] for line in spec.implausible]
    for spec in [*components.values(), *shadows.values()]:
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
    raw_entries = raw.get("components") if isinstance(raw.get("components"), dict) else {}
    connections = parse_connections(config.get("connections", {}), components, raw_entries, file, errors)
    for name, shadow in shadows.items():
        errors += [f"{file}: {shadow.key}: {p}" for p in mismatches(components[name], shadow, connections)]
    errors += [f"{file}: {p}" for p in groups.problems(list(components.values()))]
    components, connections = with_shadows(components, shadows, connections)
    events = _events(config.get("events", []), components, connections, step_ns, total_ns, settings, file, errors)
    faults = _faults(config.get("faults", []), components, total_ns, file, errors)
    notes += [f"{file}: {line}" for event in events for line in event.spec.implausible]
    restarting = [n for n, spec in components.items() if spec.on_failure == "restart"]
    errors += [f"{file}: {p}" for p in frame_problems(components, connections, restarting)]
    for name, spec in components.items():
        problem = spec.cls.state_problem(spec.typed, spec.run) if restarting else None
        if problem:
            errors.append(
                f"{file}: components.{restarting[0]}.on_failure: restart needs the state of every "
                f"component, and {name} ({spec.type}) cannot give it: {problem}"
            )
    checkpoint_ns = run.get("checkpoint_every")
    if checkpoint_ns is not None and components:
        for name, spec in components.items():
            if checkpoint_ns % spec.step_ns:
                errors.append(
                    f"{file}: run.checkpoint_every: must be a multiple of every component's step "
                    f"(all are at a step boundary then); {name} steps {duration_text(spec.step_ns)}, "
                    f"got {duration_text(checkpoint_ns)}"
                )
    if run.get("expect") is not None and (problem := expect_problem(components, run["expect"])):
        errors.append(f"{file}: run.expect: {problem}")
    bus_spec = bus_config.check(config["bus"], config_dir, errors, file) if "bus" in config else None
    if bus_spec is not None and bus_spec.plaintext_beyond:
        notes.append(
            f"{file}: bus: plain TCP beyond loopback ({', '.join(bus_spec.plaintext_beyond)}), as "
            f"bus.plaintext: accept-the-risk allows: anyone on those networks can read the run's traffic"
        )
    viewer = None
    if config.get("viewer") is not None:
        problems_of_viewer: list[str] = []
        viewer = _viewer(config["viewer"], "viewer", problems_of_viewer, path.parent)
        errors += [f"{file}: {m}" for m in problems_of_viewer]
    ros2 = None
    if config.get("ros2") is not None:
        problems_of_ros2: list[str] = []
        ros2 = ros2_spec(config["ros2"], "ros2", problems_of_ros2)
        errors += [f"{file}: {m}" for m in problems_of_ros2]
        if clash := clock_clash(components, ros2, "ros2"):
            errors.append(f"{file}: {clash}")
    if not errors and notes and (strict or run["strict"]):
        why = "--strict" if strict else "run.strict: true"
        errors = notes + [
            f"{file}: {why} makes the warning above an error"
            if len(notes) == 1
            else f"{file}: {why} makes the {len(notes)} warnings above errors"
        ]
    if errors:
        raise ConfigErrors(errors)
    resolved = {
        "run": RUN.plain(run),
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
        resolved=resolved,
        packages=packages,
        notes=notes,
        record_flush_s=run["record_flush"] / NS_PER_S,
        expect=run.get("expect"),
    )


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


def _events(
    entries: list[dict],
    components: dict[str, ComponentSpec],
    connections: list,
    step_ns: int | None,
    total_ns: int | None,
    run: RunSettings,
    file: Path,
    errors: list[str],
) -> list[Event]:
    events = []
    for i, entry in enumerate(entries):
        key = f"events[{i}]"
        at_ns, target = entry["at"], entry["swap"]
        if target not in components:
            errors.append(f"{file}: {key}.swap: no component named {target!r}")
            continue
        old = components[target]
        if total_ns is not None and at_ns >= total_ns:
            errors.append(
                f"{file}: {key}.at: must be within the run, 0 <= at < run.duration, got {duration_text(at_ns)}"
            )
            continue
        if at_ns % old.step_ns:
            errors.append(
                f"{file}: {key}.at: must fall on a step boundary of {target} "
                f"(a multiple of {duration_text(old.step_ns)}), got {duration_text(at_ns)}"
            )
            continue
        new_type = entry["type"] or old.type
        try:
            handed_over = hands_over(old, new_type, registry.load(new_type, run.config_dir))
        except ConfigError as e:
            errors.append(f"{file}: {key}.type: {e.message}")
            continue
        problem = old.cls.state_problem(old.typed, old.run) if handed_over else None
        if problem:
            what = "the same type" if new_type == old.type else new_type
            errors.append(
                f"{file}: {key}.swap: a swap to {what} hands the state over, and {target} "
                f"cannot: {problem} (give another type)"
            )
            continue
        params = entry["parameters"]
        if params is None:
            params = old.parameters if handed_over else {}
        try:
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
        except ConfigErrors as e:
            errors += [f"{file}: {m}" for m in e.errors]
            continue
        problem = handover_problem(old, spec) if handed_over else None
        if problem:
            errors.append(f"{file}: {key}: {problem}")
            continue
        spec.shadow_of = old.shadow_of
        problems = check_replacement(spec, connections) + (
            mismatches(components[old.shadow_of], spec, connections) if old.shadow_of else []
        )
        if problems:
            errors += [f"{file}: {key}: {p}" for p in problems]
            continue
        events.append(Event(at_ns=at_ns, swap=target, type=new_type, parameters=params, spec=spec))
    return sorted(events, key=lambda e: e.at_ns)


def _faults(
    entries: list[dict], components: dict[str, ComponentSpec], total_ns: int | None, file: Path, errors: list[str]
) -> list[Fault]:
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
