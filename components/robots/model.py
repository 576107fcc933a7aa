"""What components make of a URDF: its path in a config, the ``bodies`` of a multibody
component, and the units of a body's joint variables (no physics engine, xml.etree only)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from components.errors import ConfigError
from components.robots.packages import PackageError, resolve_uri
from components.robots.urdf import UrdfModel, read_urdf
from components.robots.urdf_elements import UrdfError
from components.schema import Float, OneOf

PROJECT_ROOT = Path(__file__).resolve().parents[2]

# a joint's value in a config: revolute (rad) or prismatic (m); its rate likewise
# plausible: a joint within a turn either way (a bare 90 meant in degrees is not), a rate below a
# robot's fastest joints; prismatic joints within metres
JOINT_VALUE = OneOf((Float("rad", plausible=(-2 * math.pi, 2 * math.pi)), Float("m", plausible=(-10.0, 10.0))))
JOINT_RATE = OneOf((Float("rad/s", plausible=(-2 * math.pi, 2 * math.pi)), Float("m/s", plausible=(-10.0, 10.0))))
# units of a joint's position, rate and effort, by URDF joint type
JOINT_UNITS = {
    "revolute": ("rad", "rad/s", "N*m"),
    "continuous": ("rad", "rad/s", "N*m"),
    "prismatic": ("m", "m/s", "N"),
}


def resolve_urdf(value: Any, config_dir: str | Path | None, key: str, packages: Mapping | None = None) -> Path:
    """A URDF (or .xacro) path: ``package://NAME/...`` (see :mod:`components.robots.packages`),
    absolute, else relative to the config file, else to the project root."""
    if not isinstance(value, str) or not value:
        raise ConfigError(key, f"expected a URDF file path, got {value!r}")
    if value.startswith("package://"):
        try:
            return resolve_uri(value, Path(config_dir or "."), packages)
        except PackageError as e:
            raise ConfigError(key, str(e)) from None
    path = Path(value)
    if path.is_absolute():
        candidates = [path]
    else:
        candidates = [Path(config_dir or ".") / path, PROJECT_ROOT / path]
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    raise ConfigError(key, f"URDF file {value!r} not found (looked in: {', '.join(str(c) for c in candidates)})")


def read_model(value: Any, config_dir: str | Path | None, key: str, packages: Mapping | None = None) -> UrdfModel:
    """The parsed URDF a config names (see ``resolve_urdf``), its ``package://`` URIs resolved
    through ``packages`` (the run parameter ``_packages``) and the rest of the search path;
    ConfigError naming ``key``."""
    path = resolve_urdf(value, config_dir, key, packages)
    try:
        return read_urdf(path, packages)
    except UrdfError as e:
        raise ConfigError(key, str(e)) from None


def body_items(raw: Any) -> list[tuple[str, Mapping]]:
    """A ``bodies`` parameter as (name, body) pairs; ConfigError unless a mapping name -> {urdf, ...}."""
    if not isinstance(raw, Mapping) or not raw:
        raise ConfigError("bodies", f"expected a mapping body name -> body, got {raw!r}")
    for name, body in raw.items():
        if not isinstance(body, Mapping) or "urdf" not in body:
            raise ConfigError(f"bodies.{name}", f"expected a mapping with at least urdf, got {body!r}")
    return list(raw.items())


def joint_units(model: UrdfModel) -> tuple[str, str, str]:
    """Units of a body's q, qd and tau (its movable joints, URDF order): one unit when every joint
    has it (rad, rad/s, N*m when there are none), else one per joint, comma separated, which the
    SDK spreads over the elements (as ``m/s, rad/s`` over a twist)."""
    per_joint = [JOINT_UNITS[j.type] for j in model.joints if j.movable] or [JOINT_UNITS["revolute"]]
    q, qd, tau = (units[0] if len(set(units)) == 1 else ", ".join(units) for units in zip(*per_joint))
    return q, qd, tau


def kinematic_chain(model: UrdfModel, link: str) -> list:
    """URDF joints from the root link down to ``link`` (root first)."""
    by_child = {j.child: j for j in model.joints}
    chain = []
    while link in by_child:
        chain.append(by_child[link])
        link = by_child[link].parent
    return chain[::-1]


def arm_reach(model: UrdfModel, joints: list[str], end_effector: str) -> tuple[str, float]:
    """The shoulder (the first of ``joints`` along the chain to ``end_effector``) and the arm's
    reach from it (m: the sum of the joint offsets after it, an upper bound); ConfigError naming
    ``end_effector`` or ``joints`` when the link is not in the URDF or a joint does not move it."""
    if end_effector not in model.link_names:
        raise ConfigError(
            "end_effector",
            f"{end_effector!r} is not a link of {model.path.name} (links: {', '.join(model.link_names)})",
        )
    chain = kinematic_chain(model, end_effector)
    if not chain:
        raise ConfigError("end_effector", f"{end_effector!r} is the base link: expected a link the joints move")
    names = [j.name for j in chain]
    movable = model.movable_joints
    for j in joints:
        if j not in names:
            raise ConfigError(
                "joints",
                f"{j!r} does not move end_effector {end_effector!r} (its chain: "
                f"{', '.join(n for n in names if n in movable)})",
            )
    first = min(names.index(j) for j in joints)
    return chain[first].name, float(sum(math.sqrt(sum(x * x for x in j.xyz)) for j in chain[first + 1 :]))
