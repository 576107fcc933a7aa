"""Load, override and validate a run config (docs/design.md §4) into typed structures.

Every problem is collected and reported at once, each naming its key and file; nothing is
started before the whole config is valid. Unknown keys are errors, as are missing required ones.
"""
from __future__ import annotations

import datetime as dt
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from components import registry
from components.errors import ConfigError
from components.sdk import Component, Layout, Variable, resolve_parameters
from components.units import duration_ns, duration_text, to_si

RUN_KEYS = {"name": True, "epoch": True, "duration": True, "step": True,
            "algorithm": False, "realtime": False, "step_timeout": False, "start_timeout": False}
TOP_KEYS = {"run": True, "components": True, "connections": False, "bus": False, "events": False,
            "viewer": False}
COMPONENT_KEYS = {"type": True, "step": False, "parameters": False, "launch": False, "dedicated_cpu": False}
EVENT_KEYS = {"at": True, "swap": True, "type": False, "parameters": False}
BUS_KEYS = {"listen": False}
VIEWER_KEYS = {"mode": True, "file": False, "rate": False, "open_browser": False}
VIEWER_MODES = ("spawn", "web", "save", "off")
ALGORITHMS = ("jacobi", "gauss-seidel")
DEFAULTS = {"algorithm": "jacobi", "realtime": 0, "step_timeout": "10 s", "start_timeout": "60 s"}
NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
ENDPOINT = re.compile(r"^(tcp|udp|tls|quic)/(\[[0-9a-fA-F:]+\]|[A-Za-z0-9.\-]+):\d{1,5}$")
RUN_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_\-]*$")


class ConfigErrors(Exception):
    """All problems found in one config, each ``file: key: message``."""

    def __init__(self, errors: list[str]):
        super().__init__("\n".join(errors))
        self.errors = errors


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
    dedicated_cpu: bool = False   # its stepping thread on a CPU of its own (speed only, never results)

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
    section = _keys(raw, VIEWER_KEYS, where, errors, "")
    if not section or "mode" not in section:
        return None
    mode = section["mode"]
    if mode not in VIEWER_MODES:
        errors.append(f"{where}.mode: expected one of {', '.join(VIEWER_MODES)}, got {mode!r}")
        return None
    if mode == "off":
        return None
    file = section.get("file")
    if mode == "save" and not (isinstance(file, str) and file.endswith(".rrd")):
        errors.append(f"{where}.file: save needs a file name ending in .rrd (e.g. save:run.rrd), got {file!r}")
        return None
    try:
        rate = to_si(section.get("rate", 30.0), "Hz", "rate")
    except ConfigError as e:
        errors.append(f"{where}.rate: {e.message}")
        return None
    if rate <= 0:
        errors.append(f"{where}.rate: must be positive, got {section.get('rate')!r}")
        return None
    return ViewerSpec(mode=mode, file=(base / file) if file else None, rate_hz=rate,
                      open_browser=bool(section.get("open_browser", False)))


@dataclass
class Event:
    at_ns: int
    swap: str
    type: str
    parameters: dict
    spec: ComponentSpec | None = None


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
    events: list[Event] = field(default_factory=list)
    viewer: ViewerSpec | None = None
    resolved: dict = field(default_factory=dict)   # the config as written to config.yaml

    @property
    def steps(self) -> int:
        return self.duration_ns // self.step_ns


class _UniqueKeyLoader(yaml.SafeLoader):
    """YAML loader that refuses duplicate keys (PyYAML silently keeps the last one)."""


def _mapping(loader, node, deep=False):
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise yaml.constructor.ConstructorError(None, None, f"duplicate key {key!r}", key_node.start_mark)
        seen.add(key)
    return loader.construct_mapping(node, deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)


def parse_override(text: str) -> tuple[list[str], Any]:
    """``a.b.c=VALUE`` -> (["a", "b", "c"], VALUE parsed as YAML)."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise ConfigErrors([f"--set {text!r}: expected KEY=VALUE, e.g. run.duration=2s"])
    try:
        parsed = yaml.load(value, Loader=_UniqueKeyLoader) if value.strip() else ""
    except yaml.YAMLError as e:
        raise ConfigErrors([f"--set {text!r}: value is not valid YAML ({e})"]) from None
    return key.strip().split("."), parsed


def apply_overrides(raw: dict, overrides: list[str]) -> None:
    for text in overrides:
        path, value = parse_override(text)
        components = raw.get("components")
        if path[0] == "components" and len(path) > 2 and isinstance(components, dict) and path[1] not in components:
            raise ConfigErrors([f"--set {text!r}: no component {path[1]!r} (components: "
                                f"{', '.join(map(str, components)) or 'none'})"])
        node = raw
        for i, part in enumerate(path[:-1]):
            child = node.get(part) if isinstance(node, dict) else None
            if child is None:
                child = node[part] = {}
            if not isinstance(child, dict):
                raise ConfigErrors([f"--set {text!r}: {'.'.join(path[:i + 1])} is not a mapping"])
            node = child
        node[path[-1]] = value


def _yaml_problem(error: yaml.YAMLError, text: str) -> str:
    """' at line L, column C: problem', then the line and a caret under the column, each on its own line."""
    mark = getattr(error, "problem_mark", None)
    problem = " ".join(str(getattr(error, "problem", None) or error).split())
    if mark is None:
        return f": {problem}"
    context = getattr(error, "context", None)
    lines = text.splitlines()
    source = lines[mark.line] if mark.line < len(lines) else ""
    return (f" at line {mark.line + 1}, column {mark.column + 1}: {problem}"
            + (f" ({context})" if context else "") + f"\n    {source}\n    {' ' * mark.column}^")


def read_yaml(path: Path) -> dict:
    try:
        text = path.read_text()
    except OSError as e:
        raise ConfigErrors([f"{path}: cannot read config ({e.strerror})"]) from None
    try:
        raw = yaml.load(text, Loader=_UniqueKeyLoader)
    except yaml.YAMLError as e:
        raise ConfigErrors([f"{path}: not valid YAML{_yaml_problem(e, text)}"]) from None
    if not isinstance(raw, dict):
        raise ConfigErrors([f"{path}: expected a mapping with run, components, connections"])
    return raw


def load(path: str | Path, overrides: list[str] = ()) -> RunConfig:
    """Read, override and validate ``path``; raises ConfigErrors listing every problem."""
    path = Path(path)
    raw = read_yaml(path)
    apply_overrides(raw, list(overrides))
    return validate(raw, path)


def _keys(section: Any, allowed: dict[str, bool], where: str, errors: list[str], file: Path | str) -> dict:
    at = f"{file}: " if file else ""
    if not isinstance(section, dict):
        errors.append(f"{at}{where}: expected a mapping, got {section!r}")
        return {}
    for key in section:
        if key not in allowed:
            errors.append(f"{at}{where + '.' if where else ''}{key}: unknown key "
                          f"(expected one of: {', '.join(allowed)})")
    for key, required in allowed.items():
        if required and key not in section:
            errors.append(f"{at}{where + '.' if where else ''}{key}: missing required key")
    return section


def _epoch(value: Any) -> str:
    if isinstance(value, dt.datetime):
        moment = value if value.tzinfo else value.replace(tzinfo=dt.timezone.utc)
    elif isinstance(value, str):
        moment = dt.datetime.fromisoformat(value.replace("Z", "+00:00"))
        if moment.tzinfo is None:
            raise ValueError("give the time zone, e.g. 2022-09-18T12:00:00Z")
    else:
        raise ValueError(f"expected a UTC time like 2022-09-18T12:00:00Z, got {value!r}")
    return moment.astimezone(dt.timezone.utc).isoformat().replace("+00:00", "Z")


def component_spec(name: str, entry: dict, run_step_ns: int, config_dir: Path, epoch: str,
                   key: str) -> ComponentSpec:
    """Build one component's spec; ConfigErrors naming ``key.<...>`` on problems."""
    errors: list[str] = []
    type_name = entry["type"]
    try:
        cls = registry.load(type_name, config_dir)
    except ConfigError as e:
        raise ConfigErrors([f"{key}.type: {e.message}"]) from None
    step_ns = run_step_ns
    if entry.get("step") is not None:
        try:
            step_ns = duration_ns(entry["step"], "step")
        except ConfigError as e:
            errors.append(f"{key}.step: {e.message}")
        else:
            if step_ns <= 0 or step_ns % run_step_ns:
                errors.append(f"{key}.step: must be a positive integer multiple of run.step "
                              f"({run_step_ns} ns), got {entry['step']!r} ({step_ns} ns)")
    params_raw = entry.get("parameters") or {}
    if not isinstance(params_raw, dict):
        raise ConfigErrors([f"{key}.parameters: expected a mapping, got {params_raw!r}"])
    raw = {**params_raw, "_epoch": epoch, "_config_dir": str(config_dir)}
    resolved, param_errors = resolve_parameters(cls, raw)
    errors += [f"{key}.parameters.{e.key}: {e.message}" if e.key else f"{key}.parameters: {e.message}"
               for e in param_errors]
    launch = entry.get("launch", "local")
    if launch not in ("local", "external"):
        errors.append(f"{key}.launch: expected local or external, got {launch!r}")
    dedicated_cpu = entry.get("dedicated_cpu", False)
    if not isinstance(dedicated_cpu, bool):
        errors.append(f"{key}.dedicated_cpu: expected true or false, got {dedicated_cpu!r}")
    elif dedicated_cpu and launch == "external":
        errors.append(f"{key}.dedicated_cpu: only for components the orchestrator starts (launch: local); "
                      f"pin an external component where it runs (taskset)")
    if errors:
        raise ConfigErrors(errors)
    try:
        variables = cls.declare(resolved)
    except ConfigError as e:
        raise ConfigErrors([f"{key}.parameters.{e.key}: {e.message}"]) from None
    except Exception as e:  # a component's own bug or a file it cannot read: still one line, naming the key
        raise ConfigErrors([f"{key}.parameters: {type_name} cannot declare its variables: "
                            f"{type(e).__name__}: {e}"]) from None
    return ComponentSpec(name=name, type=type_name, cls=cls, step_ns=step_ns, parameters=params_raw,
                         resolved=resolved, launch=launch, dedicated_cpu=dedicated_cpu,
                         inputs=Layout([v for v in variables if v.causality == "input"]),
                         outputs=Layout([v for v in variables if v.causality == "output"]))


def validate(raw: dict, path: Path) -> RunConfig:
    errors: list[str] = []
    file = path
    _keys(raw, TOP_KEYS, "", errors, file)
    run = _keys(raw.get("run", {}), RUN_KEYS, "run", errors, file)
    run = {**DEFAULTS, **run}

    def field_of(key, convert):
        if key not in run:
            return None
        try:
            return convert(run[key])
        except ConfigError as e:
            errors.append(f"{file}: run.{key}: {e.message}")
        except ValueError as e:
            errors.append(f"{file}: run.{key}: {e}")
        return None

    name = run.get("name")
    if name is not None and not (isinstance(name, str) and RUN_NAME.match(name)):
        errors.append(f"{file}: run.name: expected letters, digits, '_' or '-', got {name!r}")
    epoch = field_of("epoch", _epoch)
    step_ns = field_of("step", lambda v: duration_ns(v, "step"))
    total_ns = field_of("duration", lambda v: duration_ns(v, "duration"))
    step_timeout = field_of("step_timeout", lambda v: duration_ns(v, "step_timeout") / 1e9)
    start_timeout = field_of("start_timeout", lambda v: duration_ns(v, "start_timeout") / 1e9)
    for key, value in (("step_timeout", step_timeout), ("start_timeout", start_timeout)):
        if value is not None and value <= 0:
            errors.append(f"{file}: run.{key}: must be positive, got {run[key]!r}")
    if step_ns is not None and step_ns <= 0:
        errors.append(f"{file}: run.step: must be positive, got {run['step']!r}")
        step_ns = None
    if total_ns is not None and total_ns <= 0:
        errors.append(f"{file}: run.duration: must be positive, got {run['duration']!r}")
    if step_ns and total_ns and total_ns % step_ns:
        errors.append(f"{file}: run.duration: must be a whole number of steps of {run['step']!r}, "
                      f"got {run['duration']!r}")
    algorithm = run.get("algorithm")
    if algorithm not in ALGORITHMS:
        errors.append(f"{file}: run.algorithm: expected one of {', '.join(ALGORITHMS)}, got {algorithm!r}")
    realtime = run.get("realtime")
    if isinstance(realtime, bool) or not isinstance(realtime, (int, float)) or not 0 <= realtime < float("inf"):
        errors.append(f"{file}: run.realtime: expected 0 (as fast as possible) or a positive "
                      f"factor of the wall clock, got {realtime!r}")

    bus = _keys(raw.get("bus") or {}, BUS_KEYS, "bus", errors, file)
    listen = bus.get("listen", ["tcp/127.0.0.1:0"])
    if not (isinstance(listen, list) and listen and all(isinstance(e, str) and ENDPOINT.match(e) for e in listen)):
        errors.append(f"{file}: bus.listen: expected a list of Zenoh endpoints like tcp/127.0.0.1:0, got {listen!r}")

    components: dict[str, ComponentSpec] = {}
    entries = raw.get("components")
    if entries is not None and not isinstance(entries, dict):
        errors.append(f"{file}: components: expected a mapping of name -> component, got {entries!r}")
        entries = {}
    config_dir = path.parent.resolve()
    for cname, entry in (entries or {}).items():
        key = f"components.{cname}"
        if not (isinstance(cname, str) and NAME.match(cname)):
            errors.append(f"{file}: {key}: component names are identifiers (letters, digits, _), got {cname!r}")
            continue
        if not _keys(entry, COMPONENT_KEYS, key, errors, file) or "type" not in entry:
            continue
        if step_ns is None or epoch is None:
            continue
        try:
            components[cname] = component_spec(cname, entry, step_ns, config_dir, epoch, key)
        except ConfigErrors as e:
            errors += [f"{file}: {m}" for m in e.errors]

    connections = _connections(raw.get("connections") or {}, components, entries or {}, file, errors)
    events = _events(raw.get("events") or [], components, connections, step_ns, total_ns, config_dir, epoch,
                     file, errors)
    viewer = None
    if raw.get("viewer") is not None:
        viewer_errors: list[str] = []
        viewer = viewer_spec(raw["viewer"], "viewer", viewer_errors, path.parent)
        errors += [f"{file}: {e}" for e in viewer_errors]

    if errors:
        raise ConfigErrors(errors)
    resolved = {
        "run": {"name": name, "epoch": epoch, "duration": duration_text(total_ns), "step": duration_text(step_ns),
                "algorithm": algorithm, "realtime": realtime, "step_timeout": f"{step_timeout} s",
                "start_timeout": f"{start_timeout} s"},
        "bus": {"listen": listen},
        "components": {n: {"type": s.type, "step": duration_text(s.step_ns), "launch": s.launch,
                           "dedicated_cpu": s.dedicated_cpu,
                           "parameters": {k: _plain(v) for k, v in s.resolved.items() if not k.startswith("_")}}
                       for n, s in components.items()},
        "connections": {f"{d}.{dv}": f"{s}.{sv}" for d, dv, s, sv in connections},
        "events": [{"at": duration_text(e.at_ns), "swap": e.swap, "type": e.type, "parameters": e.parameters}
                   for e in events],
    }
    if viewer is not None:
        resolved["viewer"] = {"mode": viewer.mode, "rate": f"{viewer.rate_hz} Hz",
                              **({"file": str(viewer.file)} if viewer.file else {})}
    return RunConfig(path=path, name=name, epoch=epoch, duration_ns=total_ns, step_ns=step_ns,
                     algorithm=algorithm, realtime=float(realtime), step_timeout_s=step_timeout,
                     start_timeout_s=start_timeout, components=components, connections=connections,
                     listen=listen, events=events, viewer=viewer, resolved=resolved)


def _plain(value: Any) -> Any:
    """numpy values to plain YAML-able values."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def check_replacement(spec: ComponentSpec, connections: list[tuple[str, str, str, str]]) -> list[str]:
    """Problems that keep ``spec`` from replacing the component of that name in these connections."""
    problems = []
    for d, dv, s, sv in connections:
        for comp, var, layout, causality in ((d, dv, spec.inputs, "input"), (s, sv, spec.outputs, "output")):
            if comp == spec.name and var not in layout.offsets:
                problems.append(f"{spec.type} has no {causality} {var!r}, which the connection "
                                f"{d}.{dv}: {s}.{sv} uses")
    return problems


def _split(ref: Any) -> tuple[str, str] | None:
    if not isinstance(ref, str) or "." not in ref:
        return None
    component, _, variable = ref.partition(".")
    return component, variable


def _connections(raw: Any, components: dict[str, ComponentSpec], entries: dict, file: Path,
                 errors: list[str]) -> list[tuple[str, str, str, str]]:
    if not isinstance(raw, dict):
        errors.append(f"{file}: connections: expected a mapping input: output, got {raw!r}")
        return []
    result = []
    for dst, src in raw.items():
        key = f"connections.{dst}"
        d, s = _split(dst), _split(src)
        if d is None or s is None:
            errors.append(f"{file}: {key}: expected '<component>.<input>: <component>.<output>', got {dst!r}: {src!r}")
            continue
        problem = None
        for (comp, var), causality in ((d, "input"), (s, "output")):
            if comp not in entries:
                problem = f"no component named {comp!r} (components: {', '.join(entries)})"
            elif comp in components:
                spec = components[comp]
                v = spec.variables.get(var)
                if v is None or v.causality != causality:
                    names = [x.name for x in (spec.inputs if causality == "input" else spec.outputs).variables]
                    problem = (f"{comp} ({spec.type}) has no {causality} {var!r} "
                               f"(its {causality}s: {', '.join(names) or 'none'})")
            if problem:
                break
        if problem:
            errors.append(f"{file}: {key}: {problem}")
            continue
        if d[0] in components and s[0] in components:
            dv, sv = components[d[0]].variables[d[1]], components[s[0]].variables[s[1]]
            if dv.size != sv.size:
                errors.append(f"{file}: {key}: shape mismatch: input {dst} is {dv.shape}, output {src} is {sv.shape}")
                continue
            result.append((d[0], d[1], s[0], s[1]))
    return result


def _events(raw: Any, components: dict[str, ComponentSpec], connections: list, step_ns: int | None,
            total_ns: int | None, config_dir: Path, epoch: str | None, file: Path, errors: list[str]) -> list[Event]:
    if not isinstance(raw, list):
        errors.append(f"{file}: events: expected a list, got {raw!r}")
        return []
    events = []
    for i, entry in enumerate(raw):
        key = f"events[{i}]"
        if not _keys(entry, EVENT_KEYS, key, errors, file) or "at" not in entry or "swap" not in entry:
            continue
        try:
            at_ns = duration_ns(entry["at"], "at")
        except ConfigError as e:
            errors.append(f"{file}: {key}.at: {e.message}")
            continue
        target = entry["swap"]
        if target not in components:
            errors.append(f"{file}: {key}.swap: no component named {target!r}")
            continue
        old = components[target]
        if at_ns < 0 or (total_ns is not None and at_ns >= total_ns):
            errors.append(f"{file}: {key}.at: must be within the run, 0 <= at < run.duration, got {entry['at']!r}")
            continue
        if at_ns % old.step_ns:
            errors.append(f"{file}: {key}.at: must fall on a step boundary of {target} "
                          f"(a multiple of {old.step_ns / 1e6:g} ms), got {entry['at']!r}")
            continue
        new_type = entry.get("type", old.type)
        params = entry.get("parameters", old.parameters if new_type == old.type else {})
        try:
            spec = component_spec(target, {"type": new_type, "parameters": params,
                                           "step": duration_text(old.step_ns)}, step_ns, config_dir, epoch, key)
        except ConfigErrors as e:
            errors += [f"{file}: {m}" for m in e.errors]
            continue
        problems = check_replacement(spec, connections)
        if problems:
            errors += [f"{file}: {key}: {p}" for p in problems]
            continue
        events.append(Event(at_ns=at_ns, swap=target, type=new_type, parameters=params, spec=spec))
    return sorted(events, key=lambda e: e.at_ns)
