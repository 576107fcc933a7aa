"""The run's bodies, written once: a component whose type draws them (its ``scene_parameter``: the
camera's ``bodies``, name -> URDF) and whose config leaves them out gets the bodies of the one
component whose type names them (its ``bodies_parameter``: the dynamics'). The filled parameters
are the config's from then on: the recording's config.yaml, the processes and the swaps see them."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from components import registry
from components.errors import ConfigError


def fill_scenes(config: dict, config_dir: Path, file: Path, errors: list[str]) -> None:
    """Fill (in ``config``) the scene of each component, shadow and swap event that leaves it out (absent or
    null) from the run's bodies; an error when two components name bodies (which scene is meant?)."""
    entries = config.get("components") or {}
    types = {name: _type(entry.get("type"), config_dir) for name, entry in entries.items()}
    givers = {
        name: entry["parameters"][cls.bodies_parameter]
        for name, entry in entries.items()
        if (cls := types[name]) is not None
        and cls.bodies_parameter
        and isinstance(entry["parameters"], Mapping)
        and isinstance(entry["parameters"].get(cls.bodies_parameter), Mapping)
    }
    takers = [(f"components.{name}", types[name], entry) for name, entry in entries.items()]
    takers += [
        (f"components.{name}.shadow", _type(entry["shadow"].get("type"), config_dir), entry["shadow"])
        for name, entry in entries.items()
        if isinstance(entry.get("shadow"), dict)
    ]
    for i, event in enumerate(config.get("events") or []):
        kind = event.get("type") or (entries.get(event.get("swap")) or {}).get("type")
        takers.append((f"events[{i}]", _type(kind, config_dir), event))
    for key, cls, holder in takers:
        scene, params = cls and cls.scene_parameter, holder.get("parameters")
        if not scene or not isinstance(params, Mapping) or params.get(scene) is not None or not givers:
            continue
        if len(givers) > 1:
            errors.append(
                f"{file}: {key}.parameters.{scene}: the run's bodies are in {' and '.join(givers)}: "
                f"give this one's (body name -> URDF)"
            )
            continue
        bodies = next(iter(givers.values()))
        urdfs = {
            body: value["urdf"] for body, value in bodies.items() if isinstance(value, Mapping) and "urdf" in value
        }
        holder["parameters"] = {**params, scene: urdfs}


def _type(name, config_dir: Path):
    """The component type ``name`` names, or None (component_spec reports a type that does not load)."""
    if not isinstance(name, str):
        return None
    try:
        return registry.load(name, config_dir)
    except ConfigError:
        return None
