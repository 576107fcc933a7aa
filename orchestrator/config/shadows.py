"""Shadow mode: a second instance, of any type, beside a component (``components.<c>.shadow``).

The shadow is a member of the run like any other (its own process, state, checkpoints, restarts,
swaps), named ``<c>_shadow``, placed right after ``<c>`` in config order. It gets the main's
connected inputs from the same sources (so it steps k on exactly the inputs ``<c>`` steps k on,
under Jacobi and Gauss-Seidel alike), and nothing reads its outputs: they are recorded as
``<c>_shadow.<output>`` and never feed the loop. A connection of ``<c>`` to itself becomes one
of the shadow to itself: the loop a component closes on itself is part of what is shadowed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from components import schedule
from components.units import unit_scale
from orchestrator.config.yaml_file import ConfigErrors

if TYPE_CHECKING:
    from orchestrator.config.specs import ComponentSpec

SUFFIX = "_shadow"


def shadow_name(main: str) -> str:
    return main + SUFFIX


def shadow_spec(
    main: ComponentSpec, entry: dict, entries: dict, build: Callable[[str, dict, str], ComponentSpec]
) -> ComponentSpec:
    """The spec of ``main``'s shadow from its ``entry`` (config.SHADOW converted); its step and
    on_failure are the main's, the orchestrator starts it, in a process of its own. ``entries``: the config's components;
    ``build(name, entry, key)``: component_specs.component_spec."""
    name, key = shadow_name(main.name), f"components.{main.name}.shadow"
    if name in entries:
        raise ConfigErrors(
            [
                f"{key}: its outputs are recorded as {name}.<output>, and a component is named "
                f"{name!r} already (rename it)"
            ]
        )
    spec = build(
        name,
        {
            **entry,
            "step": main.step_ns,
            "launch": "local",
            "dedicated_cpu": False,
            "on_failure": main.on_failure,
            "process": None,
        },
        key,
    )
    spec.shadow_of = main.name
    return spec


def mismatches(main: ComponentSpec, shadow: ComponentSpec, connections) -> list[str]:
    """Why ``shadow`` cannot run beside ``main``: every input of ``main`` that is connected must
    exist in it with the same shape and unit, and every output ``main`` declares too."""
    connected = dict.fromkeys(dv for d, dv, _, _ in connections if d == main.name)
    wanted = [(main.variables[v], shadow.inputs, "input") for v in connected]
    wanted += [(v, shadow.outputs, "output") for v in main.outputs.variables]
    problems = []
    for expected, layout, causality in wanted:
        given = next((v for v in layout.variables if v.name == expected.name), None)
        what = f"{causality} {expected.name!r}: expected shape {expected.shape} in {expected.unit} (as {main.name}, {main.type})"
        if given is None:
            problems.append(f"{what}, {shadow.type} has no such {causality}")
        elif given.shape != expected.shape or not same_unit(given.unit, expected.unit):
            problems.append(f"{what}, got shape {given.shape} in {given.unit} ({shadow.type})")
    return problems


def same_unit(a: str, b: str) -> bool:
    """Equal, equal once parsed (``N*m``, ``m*N``), or ``1`` (generic blocks declare it for any)."""
    scales = unit_scale(a), unit_scale(b)
    return a == b or "1" in (a, b) or (None not in scales and scales[0] == scales[1])


def connections_of(main: str, connections) -> list[tuple[str, str, str, str]]:
    """The shadow's connections: the main's inputs, from the same outputs (its own for a
    connection of the main to itself)."""
    shadow = shadow_name(main)
    return [(shadow, dv, shadow if s == main else s, sv) for d, dv, s, sv in connections if d == main]


def with_shadows(
    components: dict[str, ComponentSpec], shadows: dict[str, ComponentSpec], connections: list
) -> tuple[dict[str, ComponentSpec], list]:
    """The components with each shadow (``shadows``: main name -> spec) right after its main, so
    that Gauss-Seidel gives it the main's inputs (schedule.routes reads the order), and the
    connections with the shadows'."""
    ordered = {}
    for name, spec in components.items():
        ordered[name] = spec
        if name in shadows:
            ordered[shadows[name].name] = shadows[name]
    return ordered, connections + [c for name in shadows for c in connections_of(name, connections)]


def initialization_order(components: dict[str, ComponentSpec], connections) -> list[str]:
    """schedule.initialization_order, each shadow right after its main: it initializes on the very
    inputs the main did (a shadow is a source of nothing, so nothing waits for it)."""
    mains = [n for n, s in components.items() if not s.shadow_of]
    order = schedule.initialization_order(mains, [c for c in connections if c[0] in mains])
    shadows = {s.shadow_of: n for n, s in components.items() if s.shadow_of}
    return [n for main in order for n in (main, *([shadows[main]] if main in shadows else []))]
