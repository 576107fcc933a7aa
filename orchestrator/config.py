"""Load, override and validate a run config (docs/design.md §4) into typed structures.

Every problem is collected and reported at once, each naming its key and file; nothing is
started before the whole config is valid. Unknown keys are errors, as are missing required ones.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


from components import registry
from components.constants import NS_PER_S
from components.errors import ConfigError
from components.schema import (Anything, Bool, Duration, Float, Int, ListOf, MapOf, OneOf, Parameter, Record,
                               Str, UtcTime, markdown)
from components.sdk import Component, Layout, Variable, run_parameters
from components.units import duration_text
from orchestrator import bus_config
from orchestrator.bus_config import BusSpec
from orchestrator.config_file import ConfigErrors, apply_overrides, read_yaml
from orchestrator.connections import _connections, check_replacement, hands_over, handover_problem
from orchestrator.shadows import mismatches, shadow_spec, with_shadows

ALGORITHMS = ("jacobi", "gauss-seidel")
MAX_STEPS = 10 ** 12   # steps in a run: beyond, a typo (a duration in the wrong unit), not an experiment
VIEWER_MODES = ("spawn", "web", "save", "off")
NAME = r"[A-Za-z][A-Za-z0-9_]*"
ENDPOINT = r"(tcp|udp|tls|quic)/(\[[0-9a-fA-F:]+\]|[A-Za-z0-9.\-]+):\d{1,5}"

RUN = Record("run", (
    Parameter("name", Str(pattern=r"[A-Za-z0-9][A-Za-z0-9_\-]*", hint="letters, digits, '_' or '-'"),
              description="the run's name: its recording folder and bus keys"),
    Parameter("epoch", UtcTime(), description="UTC time of t = 0, e.g. 2022-09-18T12:00:00Z"),
    Parameter("duration", Duration(), description="simulated time, a whole number of steps"),
    Parameter("step", Duration(), description="communication step; components may take multiples of it"),
    Parameter("algorithm", Str(ALGORITHMS), default="jacobi",
              description="jacobi: all step on the last outputs; gauss-seidel: in config order, on the newest"),
    Parameter("realtime", Float(minimum=0.0), default=0.0,
              description="0: as fast as possible; k: paced at k times the wall clock"),
    Parameter("step_timeout", Duration(), default="10 s",
              description="wall time a component may take for one step before the run fails"),
    Parameter("start_timeout", Duration(), default="3 min",
              description="wall time a component may take to start and initialize (a first run on a "
                          "machine compiles the kernels: 20-45 s on 2 cores)"),
    Parameter("join_timeout", Duration(), default="5 min",
              description="wall time a launch: external component may take to join (orchestrator join), "
                          "and to join again after it was lost"),
    Parameter("checkpoint_every", Duration(), default=None,
              description="simulated time between checkpoints, when a component has on_failure: restart "
                          "(none: the start is the only one)"),
    Parameter("max_restarts", Int(minimum=0), default=3,
              description="restarts from a checkpoint before a failure ends the run"),
    Parameter("record_flush", Duration(), default="1 s",
              description="wall time at most between the recording's writes to disk (besides every 1000 rows): "
                          "a full disk or a kill loses no more than this"),
    Parameter("packages", MapOf(Str(hint="a directory"), "package name"), default={},
              description="ROS packages by name -> directory (relative to the config file), for package:// URIs "
                          "and $(find NAME) in URDFs; looked up before ROS_PACKAGE_PATH and installed packages"),
), description="the run's identity and timing (``run:``)")
BUS = Record("bus", (
    Parameter("listen", ListOf(Str(pattern=ENDPOINT, hint="a Zenoh endpoint like tcp/127.0.0.1:0"), min_items=1),
              default=["tcp/127.0.0.1:0"], description="where the orchestrator listens (loopback by default; "
                                                       "another address is for components on other hosts)"),
    Parameter("connect", ListOf(Str(pattern=ENDPOINT, hint="a Zenoh endpoint like tcp/192.0.2.7:7447")), default=[],
              description="endpoints the orchestrator links to besides the router (other peers)"),
    Parameter("mode", Str(("peer", "client")), default="peer",
              description="peer: the run's processes link to each other directly; client: everything goes "
                          "through bus.router"),
    Parameter("router", Str(pattern=ENDPOINT, hint="a Zenoh endpoint like tcp/192.0.2.7:7447"), default=None,
              description="a router every process of the run links to (orchestrator router), for hosts that "
                          "cannot reach each other"),
    Parameter("lease", Duration(), default="10 s",
              description="a link silent this long counts as dead: its component is lost (keep-alives every quarter)"),
    Parameter("tls", OneOf((Bool(), Str(("auto",)))), default="auto",
              description="mutual TLS on every link (true | false); auto: on when the bus leaves loopback "
                          "(bus.listen, bus.connect or bus.router)"),
    Parameter("plaintext", Str(("refuse", "accept-the-risk")), default="refuse",
              description="tls: false with the bus beyond loopback is refused unless this says accept-the-risk "
                          "(then every process listens in plain TCP, and the run warns at start)"),
    Parameter("ca", Record("ca", (
        Parameter("certificate", Str(hint="a PEM file"), description="the CA's certificate (PEM)"),
        Parameter("key", Str(hint="a PEM file"), description="its private key (PEM)"),
    ), description="your CA, to issue the run's certificates (``bus.ca``)"), default=None,
              description="issue the run's certificates from your CA (default: a CA made for the run)"),
), description="the Zenoh bus (``bus:``)")
VIEWER = Record("viewer", (
    Parameter("mode", Str(VIEWER_MODES), description="spawn a Rerun viewer, serve it on the web, save a .rrd, or off"),
    Parameter("file", Str(pattern=r".+\.rrd", hint="a file name ending in .rrd"), default=None,
              description="the recording of save, relative to the config file"),
    Parameter("rate", Float("Hz", positive=True), default=30.0, description="frames per second of simulated time"),
    Parameter("open_browser", Bool(), default=False, description="web: open the viewer in a browser"),
), description="the Rerun live view (``viewer:``, or ``--view``)")
SHADOW = Record("shadow", (
    Parameter("type", Str(hint="a component type name"),
              description="any type with the component's connected inputs and all its outputs, same shapes and units"),
    Parameter("parameters", Anything(), default={}, description="the type's parameters (orchestrator describe TYPE)"),
), description="a second instance on the component's inputs at every step, in a process of its own; recorded "
               "as ``<component>_shadow.<output>``, it feeds nothing (``components.<name>.shadow``)")
COMPONENT = Record("component", (
    Parameter("type", Str(hint="a component type name"),
              description="a built-in type (orchestrator types), module:Class or file.py:Class"),
    Parameter("step", Duration(), default=None, description="its step, a multiple of run.step (default: run.step)"),
    Parameter("parameters", Anything(), default={}, description="the type's parameters (orchestrator describe TYPE)"),
    Parameter("launch", Str(("local", "external")), default="local",
              description="local: the orchestrator starts it; external: you do (orchestrator ps prints how)"),
    Parameter("dedicated_cpu", OneOf((Bool(), Str(("process",)))), default=False,
              description="true: its stepping thread on a CPU of its own, for a component that computes most of "
                          "each step; process: its whole process there, its bus threads too, for one that waits "
                          "for its inputs much of each step (speed only, never results)"),
    Parameter("on_failure", Str(("stop", "restart")), default="stop",
              description="when it dies or hangs: stop the run, or restart the run from its last checkpoint"),
    Parameter("shadow", SHADOW, default=None,
              description="a second instance run beside it on the same inputs, recorded, never fed back"),
), description="one component (``components.<name>``)")
EVENT = Record("event", (
    Parameter("at", Duration(positive=False), description="simulated time of the swap, on a step of the component"),
    Parameter("swap", Str(), description="the component replaced"),
    Parameter("type", Str(hint="a component type name"), default=None, description="the new type (default: the same)"),
    Parameter("parameters", Anything(), default=None,
              description="the new parameters (default: the old ones when the state is handed over: the same "
                          "type or one that takes its state; none for another)"),
), description="a swap during the run (``events:``)")
FAULT_KINDS = ("crash", "hang", "nan", "delay")
FAULT = Record("fault", (
    Parameter("at", Duration(positive=False), description="simulated time: the component's first step at or after it"),
    Parameter("component", Str(), description="the component that fails"),
    Parameter("kind", Str(FAULT_KINDS), description="crash: SIGKILL; hang: never finishes the step; "
                                                    "nan: a NaN output; delay: the step takes longer"),
    Parameter("duration", Duration(), default=None, description="delay: the wall time the step is held"),
), description="an injected failure, once per run (``faults:``)")
CONFIG = Record("config", (
    Parameter("run", RUN, description="identity and timing"),
    Parameter("components", MapOf(COMPONENT, "component name", key_pattern=NAME), description="the components by name"),
    Parameter("connections", MapOf(Str(hint="'<component>.<output>'"), "input"), default={},
              description="'<component>.<input>: <component>.<output>'"),
    Parameter("bus", BUS, default={}, description="the Zenoh bus"),
    Parameter("events", ListOf(EVENT), default=[], description="swaps during the run"),
    Parameter("faults", ListOf(FAULT), default=[], description="injected failures, to test a setup's recovery"),
    Parameter("viewer", VIEWER, default=None, description="the Rerun live view"),
), description="a run config")


@dataclass
class ComponentSpec:
    name: str
    type: str
    cls: type[Component]
    step_ns: int
    parameters: dict        # raw, as in the config (+ injected run parameters)
    resolved: dict          # validated, SI
    inputs: Layout
    outputs: Layout
    launch: str = "local"
    dedicated_cpu: bool | str = False   # true: its stepping thread on a CPU of its own; "process": all its threads
    on_failure: str = "stop"      # or "restart": the run goes back to its last checkpoint
    shadow_of: str | None = None  # the component this one shadows (orchestrator/shadows.py)

    @property
    def key(self) -> str:
        """Its entry in the config file."""
        return f"components.{self.shadow_of}.shadow" if self.shadow_of else f"components.{self.name}"

    @property
    def variables(self) -> dict[str, Variable]:
        return {v.name: v for v in self.inputs.variables + self.outputs.variables}


@dataclass
class ViewerSpec:
    """The Rerun live view: ``mode`` spawn | web | save; ``file`` for save; ``rate_hz`` of sim time."""
    mode: str
    file: Path | None
    rate_hz: float
    open_browser: bool = False


def viewer_spec(raw: Any, where: str, errors: list[str], base: Path) -> ViewerSpec | None:
    """Parse a ``viewer:`` section or a ``--view`` value (``spawn``, ``web``, ``save:FILE.rrd``)."""
    if isinstance(raw, str):
        mode, _, file = raw.partition(":")
        raw = {"mode": mode, **({"file": file} if file else {})}
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
    file = section["file"]
    return ViewerSpec(mode=section["mode"], file=(base / file) if file else None, rate_hz=section["rate"],
                      open_browser=section["open_browser"])


@dataclass
class Event:
    at_ns: int
    swap: str
    type: str
    parameters: dict
    spec: ComponentSpec | None = None


@dataclass(frozen=True)
class Fault:
    """An injected failure: ``component`` fails in its first step at or after ``at_ns``."""
    at_ns: int
    component: str
    kind: str
    duration_ns: int | None = None


@dataclass
class RunConfig:
    path: Path
    name: str
    epoch: str
    duration_ns: int
    step_ns: int
    algorithm: str
    realtime: float
    step_timeout_s: float
    start_timeout_s: float
    components: dict[str, ComponentSpec]
    connections: list[tuple[str, str, str, str]]  # (dst component, dst var, src component, src var)
    listen: list[str]
    bus: BusSpec
    join_timeout_s: float
    events: list[Event] = field(default_factory=list)
    faults: list[Fault] = field(default_factory=list)
    checkpoint_ns: int | None = None
    max_restarts: int = 3
    viewer: ViewerSpec | None = None
    resolved: dict = field(default_factory=dict)   # the config as written to config.yaml
    packages: dict = field(default_factory=dict)   # run.packages: name -> absolute directory
    notes: list = field(default_factory=list)      # warnings found by the check (physics), one line each
    record_flush_s: float = 1.0                    # run.record_flush

    @property
    def steps(self) -> int:
        return self.duration_ns // self.step_ns

    @property
    def run_parameters(self) -> dict[str, str]:
        """What every component gets besides its own parameters (sdk.RUN_PARAMETERS)."""
        return run_parameters(self.epoch, self.path.parent.resolve(), self.packages)


def load(path: str | Path, overrides: list[str] = (), full: bool = False) -> RunConfig:
    """Read, override and validate ``path``; raises ConfigErrors listing every problem. ``full``
    (``orchestrator check``): the components also load what they would at the start (URDFs into
    DART), so that what fails there fails here."""
    path = Path(path)
    raw = read_yaml(path)
    apply_overrides(raw, list(overrides))
    return validate(raw, path, full)


def component_spec(name: str, entry: dict, run_step_ns: int, config_dir: Path, epoch: str,
                   key: str, packages: dict | None = None) -> ComponentSpec:
    """One component's spec from its entry as COMPONENT converts it; ConfigErrors naming ``key.<...>``."""
    errors: list[str] = []
    type_name = entry["type"]
    try:
        cls = registry.load(type_name, config_dir)
    except ConfigError as e:
        raise ConfigErrors([f"{key}.type: {e.message}"]) from None
    step_ns = run_step_ns if entry["step"] is None else entry["step"]
    if step_ns % run_step_ns:
        errors.append(f"{key}.step: must be a positive integer multiple of run.step "
                      f"({duration_text(run_step_ns)}), got {duration_text(step_ns)}")
    params_raw = entry["parameters"]
    if not isinstance(params_raw, dict):
        raise ConfigErrors([f"{key}.parameters: expected a mapping, got {params_raw!r}"])
    unresolved = None
    try:
        resolved = registry.resolve(cls, params_raw, epoch=epoch, config_dir=config_dir, packages=packages)
    except registry.Unresolved as e:
        unresolved = e
    if unresolved and unresolved.stage == "parameters":
        errors += [f"{key}.parameters.{e.key}: {e.message}" if e.key else f"{key}.parameters: {e.message}"
                   for e in unresolved.errors]
    if entry["dedicated_cpu"] and entry["launch"] == "external":
        errors.append(f"{key}.dedicated_cpu: only for components the orchestrator starts (launch: local); "
                      f"pin an external component where it runs (taskset)")
    if errors:
        raise ConfigErrors(errors)
    if unresolved:   # declare failed; a component's own bug or a file it cannot read is one line too
        e = unresolved.errors[0]
        raise ConfigErrors([f"{key}.parameters.{e.key}: {e.message}" if isinstance(e, ConfigError) else
                            f"{key}.parameters: {type_name} cannot declare its variables: {type(e).__name__}: {e}"])
    return ComponentSpec(name=name, type=type_name, cls=cls, step_ns=step_ns, parameters=params_raw,
                         resolved=resolved.params, launch=entry["launch"], dedicated_cpu=entry["dedicated_cpu"],
                         on_failure=entry["on_failure"], inputs=resolved.inputs, outputs=resolved.outputs)


def validate(raw: dict, path: Path, full: bool = False) -> RunConfig:
    """The config checked against CONFIG, then across its parts (components, connections, events)."""
    file = path
    config, problems = CONFIG.resolve(raw)
    errors = [f"{file}: {e.key}: {e.message}" for e in problems]
    run = config.get("run", {})
    step_ns, total_ns, epoch = run.get("step"), run.get("duration"), run.get("epoch")
    if step_ns and total_ns and total_ns % step_ns:
        errors.append(f"{file}: run.duration: must be a whole number of steps of {duration_text(step_ns)}, "
                      f"got {raw['run']['duration']!r}")
    elif step_ns and total_ns and total_ns // step_ns > MAX_STEPS:
        errors.append(f"{file}: run.duration: {total_ns // step_ns:.3g} steps of {duration_text(step_ns)}; at most "
                      f"{MAX_STEPS:.0e} steps (at a million steps per second, 11 days of wall time)")
    components: dict[str, ComponentSpec] = {}
    config_dir = path.parent.resolve()
    packages = {}
    for package, directory in (run.get("packages") or {}).items():
        where = (config_dir / directory).resolve()
        if not where.is_dir():
            errors.append(f"{file}: run.packages.{package}: directory {directory!r} not found ({where})")
        packages[package] = str(where)
    entries = config.get("components", {})
    shadows: dict[str, ComponentSpec] = {}   # main's name -> its shadow
    if step_ns is not None and epoch is not None:
        for name, entry in entries.items():
            try:
                components[name] = component_spec(name, entry, step_ns, config_dir, epoch, f"components.{name}",
                                                  packages)
                if entry["shadow"] is not None:
                    shadows[name] = shadow_spec(components[name], entry["shadow"], entries, lambda n, e, key: (
                        component_spec(n, e, step_ns, config_dir, epoch, key, packages)))
            except ConfigErrors as e:
                errors += [f"{file}: {m}" for m in e.errors]
    notes = []
    for spec in [*components.values(), *shadows.values()]:
        key = f"{spec.key}.parameters"
        try:
            notes += [f"{file}: {key}.{note}" for note in spec.cls.preflight(spec.resolved, spec.step_ns / 1e9, full)]
        except ConfigError as e:
            errors.append(f"{file}: {key}.{e.key}: {e.message}" if e.key else f"{file}: {key}: {e.message}")
        except Exception as e:   # a component's own check failing is a line too, not a traceback
            errors.append(f"{file}: {key}: {spec.type} cannot load its model: {type(e).__name__}: {e}")
    raw_entries = raw.get("components") if isinstance(raw.get("components"), dict) else {}
    connections = _connections(config.get("connections", {}), components, raw_entries, file, errors)
    for name, shadow in shadows.items():
        errors += [f"{file}: {shadow.key}: {p}" for p in mismatches(components[name], shadow, connections)]
    components, connections = with_shadows(components, shadows, connections)
    events = _events(config.get("events", []), components, connections, step_ns, total_ns, config_dir, epoch,
                     file, errors, packages)
    faults = _faults(config.get("faults", []), components, total_ns, file, errors)
    restarting = [n for n, spec in components.items() if spec.on_failure == "restart"]
    for name, spec in components.items():
        problem = spec.cls.state_problem(spec.resolved) if restarting else None
        if problem:
            errors.append(f"{file}: components.{restarting[0]}.on_failure: restart needs the state of every "
                          f"component, and {name} ({spec.type}) cannot give it: {problem}")
    checkpoint_ns = run.get("checkpoint_every")
    if checkpoint_ns is not None and components:
        for name, spec in components.items():
            if checkpoint_ns % spec.step_ns:
                errors.append(f"{file}: run.checkpoint_every: must be a multiple of every component's step "
                              f"(all are at a step boundary then); {name} steps {duration_text(spec.step_ns)}, "
                              f"got {duration_text(checkpoint_ns)}")
    bus_spec = bus_config.check(config["bus"], config_dir, errors, file) if "bus" in config else None
    if bus_spec is not None and bus_spec.plaintext_beyond:
        notes.append(f"{file}: bus: plain TCP beyond loopback ({', '.join(bus_spec.plaintext_beyond)}), as "
                     f"bus.plaintext: accept-the-risk allows: anyone on those networks can read the run's traffic")
    viewer = None
    if config.get("viewer") is not None:
        problems_of_viewer: list[str] = []
        viewer = _viewer(config["viewer"], "viewer", problems_of_viewer, path.parent)
        errors += [f"{file}: {m}" for m in problems_of_viewer]
    if errors:
        raise ConfigErrors(errors)
    resolved = {
        "run": RUN.plain(run),
        "bus": BUS.plain(config["bus"]),
        "components": {n: _resolved_entry(s, shadows.get(n)) for n, s in components.items() if not s.shadow_of},
        "connections": {f"{d}.{dv}": f"{s}.{sv}" for d, dv, s, sv in connections if not components[d].shadow_of},
        "events": [{"at": duration_text(e.at_ns), "swap": e.swap, "type": e.type,
                    "parameters": e.spec.cls.schema.plain(e.spec.resolved)} for e in events],
        "faults": [FAULT.plain({"at": f.at_ns, "component": f.component, "kind": f.kind, "duration": f.duration_ns})
                   for f in faults],
    }
    if viewer is not None:
        resolved["viewer"] = VIEWER.plain(config["viewer"])
    return RunConfig(path=path, name=run["name"], epoch=epoch, duration_ns=total_ns, step_ns=step_ns,
                     algorithm=run["algorithm"], realtime=run["realtime"], step_timeout_s=run["step_timeout"] / 1e9,
                     start_timeout_s=run["start_timeout"] / 1e9, components=components, connections=connections,
                     listen=config["bus"]["listen"], bus=bus_spec, join_timeout_s=run["join_timeout"] / 1e9,
                     events=events, faults=faults, checkpoint_ns=checkpoint_ns,
                     max_restarts=run["max_restarts"], viewer=viewer, resolved=resolved, packages=packages, notes=notes,
                     record_flush_s=run["record_flush"] / NS_PER_S)


def _resolved_entry(spec: ComponentSpec, shadow: ComponentSpec | None) -> dict:
    """A component's entry in the resolved config.yaml, its shadow nested in it."""
    entry = {**COMPONENT.plain({"type": spec.type, "step": spec.step_ns, "launch": spec.launch,
                                "dedicated_cpu": spec.dedicated_cpu, "on_failure": spec.on_failure}),
             "parameters": spec.cls.schema.plain(spec.resolved)}
    del entry["shadow"]
    if shadow is not None:
        entry["shadow"] = {"type": shadow.type, "parameters": shadow.cls.schema.plain(shadow.resolved)}
    return entry


def _events(entries: list[dict], components: dict[str, ComponentSpec], connections: list, step_ns: int | None,
            total_ns: int | None, config_dir: Path, epoch: str | None, file: Path, errors: list[str],
            packages: dict | None = None) -> list[Event]:
    events = []
    for i, entry in enumerate(entries):
        key = f"events[{i}]"
        at_ns, target = entry["at"], entry["swap"]
        if target not in components:
            errors.append(f"{file}: {key}.swap: no component named {target!r}")
            continue
        old = components[target]
        if total_ns is not None and at_ns >= total_ns:
            errors.append(f"{file}: {key}.at: must be within the run, 0 <= at < run.duration, "
                          f"got {duration_text(at_ns)}")
            continue
        if at_ns % old.step_ns:
            errors.append(f"{file}: {key}.at: must fall on a step boundary of {target} "
                          f"(a multiple of {duration_text(old.step_ns)}), got {duration_text(at_ns)}")
            continue
        new_type = entry["type"] or old.type
        try:
            handed_over = hands_over(old, new_type, registry.load(new_type, config_dir))
        except ConfigError as e:
            errors.append(f"{file}: {key}.type: {e.message}")
            continue
        problem = old.cls.state_problem(old.resolved) if handed_over else None
        if problem:
            what = "the same type" if new_type == old.type else new_type
            errors.append(f"{file}: {key}.swap: a swap to {what} hands the state over, and {target} "
                          f"cannot: {problem} (give another type)")
            continue
        params = entry["parameters"]
        if params is None:
            params = old.parameters if handed_over else {}
        try:
            spec = component_spec(target, {"type": new_type, "parameters": params, "step": old.step_ns,
                                           "launch": "local", "dedicated_cpu": False, "on_failure": old.on_failure},
                                  step_ns, config_dir, epoch, key, packages)
        except ConfigErrors as e:
            errors += [f"{file}: {m}" for m in e.errors]
            continue
        problem = handover_problem(old, spec) if handed_over else None
        if problem:
            errors.append(f"{file}: {key}: {problem}")
            continue
        spec.shadow_of = old.shadow_of
        problems = check_replacement(spec, connections) + (
            mismatches(components[old.shadow_of], spec, connections) if old.shadow_of else [])
        if problems:
            errors += [f"{file}: {key}: {p}" for p in problems]
            continue
        events.append(Event(at_ns=at_ns, swap=target, type=new_type, parameters=params, spec=spec))
    return sorted(events, key=lambda e: e.at_ns)


def _faults(entries: list[dict], components: dict[str, ComponentSpec], total_ns: int | None, file: Path,
            errors: list[str]) -> list[Fault]:
    faults = []
    for i, entry in enumerate(entries):
        key = f"faults[{i}]"
        if entry["component"] not in components:
            errors.append(f"{file}: {key}.component: no component named {entry['component']!r} "
                          f"(components: {', '.join(components)})")
        elif total_ns is not None and entry["at"] >= total_ns:
            errors.append(f"{file}: {key}.at: must be within the run, 0 <= at < run.duration, "
                          f"got {duration_text(entry['at'])}")
        elif entry["kind"] == "nan" and not components[entry["component"]].outputs.size:
            errors.append(f"{file}: {key}.kind: {entry['component']} has no output to make NaN")
        elif (entry["kind"] == "delay") != (entry["duration"] is not None):
            errors.append(f"{file}: {key}.duration: " + ("a delay needs one (e.g. duration: 2 s)"
                          if entry["kind"] == "delay" else f"only a delay has one, not a {entry['kind']}"))
        else:
            faults.append(Fault(entry["at"], entry["component"], entry["kind"], entry["duration"]))
    return sorted(faults, key=lambda f: f.at_ns)


DOCS_START = "<!-- config reference: python -m orchestrator.config --docs -->"
DOCS_END = "<!-- end of config reference -->"


def write_docs(design: Path = Path(__file__).resolve().parents[1] / "docs" / "design.md") -> None:
    """Write CONFIG's tables into docs/design.md between the markers (they come from the declaration)."""
    head, rest = design.read_text().split(DOCS_START, 1)
    tail = rest.split(DOCS_END, 1)[1]
    design.write_text(f"{head}{DOCS_START}\n{markdown(CONFIG)}\n{DOCS_END}{tail}")


if __name__ == "__main__":
    import sys
    if sys.argv[1:] != ["--docs"]:
        raise SystemExit("usage: python -m orchestrator.config --docs   (writes the config tables into docs/design.md)")
    write_docs()
