"""Checking connections between components (both ends exist, shapes and units agree) and what a
component's replacement (a swap) must keep: the connected variables, and, when the swap hands the
state over, the state's form and the outputs."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from components.units import unit_scale

if TYPE_CHECKING:
    from orchestrator.config.specs import ComponentSpec


def check_replacement(spec: ComponentSpec, connections: list[tuple[str, str, str, str]]) -> list[str]:
    """Problems that keep ``spec`` from replacing the component of that name in these connections."""
    problems = []
    for d, dv, s, sv in connections:
        for comp, var, layout, causality in ((d, dv, spec.inputs, "input"), (s, sv, spec.outputs, "output")):
            if comp != spec.name:
                continue
            if any(v.name == var for v in layout.frames):
                # a frame is part of no state and is not sent again to a new generation
                problems.append(
                    f"the connection {d}.{dv}: {s}.{sv} carries frames (images): a component joined "
                    f"by one cannot be swapped yet"
                )
            elif var not in layout.offsets:
                problems.append(f"{spec.type} has no {causality} {var!r}, which the connection {d}.{dv}: {s}.{sv} uses")
    return problems


def units_differ(a: str, b: str) -> bool:
    """Units both declared and read differently ("1", as generic blocks declare, matches any)."""
    scales = unit_scale(a), unit_scale(b)
    return None not in scales and "1" not in (a, b) and scales[0] != scales[1]


def hands_over(old: ComponentSpec, new_type: str, new_cls) -> bool:
    """Whether a swap of ``old`` to ``new_type`` (its class ``new_cls``) hands the state over
    (``set_state``, no ``initialize``): the same type, or one that takes the old type's state
    (``Component.takes_state_of``)."""
    return new_type == old.type or new_cls.takes_state_of(old.cls)


def handover_problem(old: ComponentSpec, new: ComponentSpec) -> str | None:
    """Why ``new`` cannot take over ``old``'s state, or None: the old instance cannot give it
    (``Component.state_problem``), or, for another type, the outputs differ (the new generation
    starts from the old one's outputs)."""
    what = "the same type" if new.type == old.type else new.type
    problem = old.cls.state_problem(old.typed, old.run)
    if problem:
        return f"a swap to {what} hands the state over, and {old.name} cannot: {problem} (give another type)"
    ours = [(v.name, v.shape) for v in old.outputs.variables]
    theirs = [(v.name, v.shape) for v in new.outputs.variables]
    if ours != theirs:
        differ = [f"{n}{list(s)}" for n, s in theirs if (n, s) not in ours][:3] + [
            f"no {n}{list(s)}" for n, s in ours if (n, s) not in theirs
        ][:3]
        return (
            f"a swap from {old.type} to {what} hands the state over, so the new outputs must be the old ones "
            f"(the same parameters), got {', '.join(differ) or 'them in another order'}"
        )
    return None


def _split(ref: Any) -> tuple[str, str] | None:
    if not isinstance(ref, str) or "." not in ref:
        return None
    component, _, variable = ref.partition(".")
    return component, variable


def parse_connections(
    raw: Any, components: dict[str, ComponentSpec], entries: dict, file: Path, errors: list[str]
) -> list[tuple[str, str, str, str]]:
    """The config's ``connections`` as (input component, input, output component, output); each
    problem (unknown names, shapes or units that differ) appended to ``errors``."""
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
                    layout = spec.inputs if causality == "input" else spec.outputs
                    names = [x.name for x in layout.variables + layout.frames]
                    problem = (
                        f"{comp} ({spec.type}) has no {causality} {var!r} "
                        f"(its {causality}s: {', '.join(names) or 'none'})"
                    )
            if problem:
                break
        if problem:
            errors.append(f"{file}: {key}: {problem}")
            continue
        if d[0] in components and s[0] in components:
            dv, sv = components[d[0]].variables[d[1]], components[s[0]].variables[s[1]]
            if dv.frame != sv.frame:
                kinds = {True: "a frame (image)", False: "a float variable"}
                errors.append(
                    f"{file}: {key}: kind mismatch: input {dst} is {kinds[dv.frame]}, output {src} is "
                    f"{kinds[sv.frame]} (a frame connects only to a frame)"
                )
                continue
            if dv.frame and (dv.shape, dv.dtype) != (sv.shape, sv.dtype):
                errors.append(
                    f"{file}: {key}: frame mismatch: input {dst} is {dv.dtype} {dv.shape}, output {src} "
                    f"is {sv.dtype} {sv.shape}"
                )
                continue
            if dv.size != sv.size:
                errors.append(f"{file}: {key}: shape mismatch: input {dst} is {dv.shape}, output {src} is {sv.shape}")
                continue
            if units_differ(dv.unit, sv.unit):
                errors.append(
                    f"{file}: {key}: unit mismatch: input {dst} is in {dv.unit}, output {src} in "
                    f"{sv.unit} (connections do not convert units)"
                )
                continue
            result.append((d[0], d[1], s[0], s[1]))
    return result
