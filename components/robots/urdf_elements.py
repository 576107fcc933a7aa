"""A URDF's ``<link>`` and ``<joint>`` elements read into :class:`UrdfLink` and :class:`UrdfJoint`:
names unique, joint types supported, numbers finite, inertias physical (positive definite, the
triangle inequality), limits given where the type needs them; each problem a :class:`UrdfError`
naming the file and the element. The model they make, and the checks of the tree they form:
:mod:`components.robots.urdf`.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from components.rotations import rpy_to_matrix

MOVABLE_TYPES = ("revolute", "continuous", "prismatic")
SUPPORTED_TYPES = MOVABLE_TYPES + ("fixed",)


class UrdfError(ValueError):
    """A URDF that cannot be used: missing, not XML, or not a tree of supported joints."""


@dataclass(frozen=True)
class UrdfJoint:
    """One URDF joint. ``lower``/``upper`` are -inf/+inf without position limits (continuous);
    ``effort`` and ``velocity`` are +inf when the URDF gives none."""

    name: str
    type: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    axis: tuple[float, float, float]
    lower: float
    upper: float
    effort: float
    velocity: float
    mimic: tuple[str, float, float] | None = None  # (joint followed, multiplier, offset)

    @property
    def movable(self) -> bool:
        return self.type in MOVABLE_TYPES


@dataclass(frozen=True)
class UrdfLink:
    """One URDF link: mass (0 without ``<inertial>``), CoM in the link frame, has collision shapes,
    and the inertia about the CoM in the link's axes (kg m^2, row-major 3x3: the inertial origin's
    rpy applied, R I R^T)."""

    name: str
    mass: float
    com: tuple[float, float, float]
    has_inertial: bool
    has_collision: bool
    inertia: tuple[float, ...] = (0.0,) * 9


def _floats(text: str | None, default: tuple[float, float, float], where: str) -> tuple[float, float, float]:
    """Three finite numbers (an xyz or rpy attribute), or ``default`` without one."""
    if text is None:
        return default
    parts = text.split()
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise UrdfError(f"{where}: expected 3 numbers, got {text!r}") from None
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise UrdfError(f"{where}: expected 3 finite numbers, got {text!r}")
    x, y, z = values
    return x, y, z


def _float(element: ET.Element, attribute: str, default: float | None, where: str) -> float:
    text = element.get(attribute)
    if text is None:
        if default is None:
            raise UrdfError(f"{where}: missing attribute {attribute!r}")
        return default
    try:
        return float(text)
    except ValueError:
        raise UrdfError(f"{where}: {attribute} expected a number, got {text!r}") from None


def _check_inertia(inertia: ET.Element, mass: float, where: str) -> np.ndarray:
    """The inertia matrix, checked: positive definite and the triangle inequality (each principal
    moment at most the sum of the other two), with a relative tolerance of 1e-9; an all-zero
    inertia is a point mass."""
    values = {a: _float(inertia, a, 0.0, f"{where} inertia") for a in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
    if not all(math.isfinite(v) for v in values.values()):
        raise UrdfError(f"{where}: inertia values must be finite, got {values}")
    matrix = np.array(
        [
            [values["ixx"], values["ixy"], values["ixz"]],
            [values["ixy"], values["iyy"], values["iyz"]],
            [values["ixz"], values["iyz"], values["izz"]],
        ]
    )
    if not np.any(matrix):  # a point mass (a sensor frame's, say): DART and Pinocchio take it
        return matrix
    moments = np.linalg.eigvalsh(matrix)
    scale = max(float(np.abs(moments).max()), 1e-300)
    if moments[0] <= 1e-12 * scale:
        raise UrdfError(
            f"{where}: the inertia is not positive definite (principal moments "
            f"{', '.join(f'{m:.6g}' for m in moments)} kg m^2; ixx {values['ixx']:g}, iyy {values['iyy']:g}, "
            f"izz {values['izz']:g})"
        )
    a, b, c = moments
    if c > a + b + 1e-9 * scale:
        raise UrdfError(
            f"{where}: the inertia breaks the triangle inequality: principal moment {c:.6g} > "
            f"{a:.6g} + {b:.6g} kg m^2 (no rigid body has it; ixx {values['ixx']:g}, "
            f"iyy {values['iyy']:g}, izz {values['izz']:g})"
        )
    return matrix


def read_links(robot: ET.Element, path: Path) -> list[UrdfLink]:
    links: list[UrdfLink] = []
    for element in robot.findall("link"):
        name = element.get("name")
        where = f"{path.name}: link {name!r}"
        if not name:
            raise UrdfError(f"{path.name}: a <link> has no name")
        if any(link.name == name for link in links):
            raise UrdfError(f"{path.name}: duplicate link name {name!r}")
        inertial = element.find("inertial")
        mass, com, I_com = 0.0, (0.0, 0.0, 0.0), np.zeros((3, 3))
        if inertial is not None:
            mass_el = inertial.find("mass")
            if mass_el is None:
                raise UrdfError(f"{where}: <inertial> without <mass>")
            mass = _float(mass_el, "value", None, f"{where} mass")
            if not (mass >= 0.0 and math.isfinite(mass)):
                raise UrdfError(f"{where}: expected a mass >= 0 kg, got {mass}")
            origin = inertial.find("origin")
            rpy = (0.0, 0.0, 0.0)
            if origin is not None:
                com = _floats(origin.get("xyz"), com, f"{where} inertial origin xyz")
                rpy = _floats(origin.get("rpy"), rpy, f"{where} inertial origin rpy")
            inertia = inertial.find("inertia")
            if inertia is None and mass > 0.0:
                raise UrdfError(f"{where}: <inertial> without <inertia>")
            if inertia is not None:
                R = rpy_to_matrix(rpy)
                I_com = R @ _check_inertia(inertia, mass, where) @ R.T
        links.append(
            UrdfLink(
                name,
                mass,
                com,
                inertial is not None,
                element.find("collision") is not None,
                tuple(I_com.ravel().tolist()),
            )
        )
    if not links:
        raise UrdfError(f"{path.name}: no <link> elements")
    return links


def read_joints(robot: ET.Element, path: Path, link_names: set[str]) -> list[UrdfJoint]:
    joints: list[UrdfJoint] = []
    children: set[str] = set()
    for element in robot.findall("joint"):
        name = element.get("name")
        kind = element.get("type")
        where = f"{path.name}: joint {name!r}"
        if not name:
            raise UrdfError(f"{path.name}: a <joint> has no name")
        if any(j.name == name for j in joints):
            raise UrdfError(f"{path.name}: duplicate joint name {name!r}")
        if kind not in SUPPORTED_TYPES:
            raise UrdfError(f"{where}: unsupported joint type {kind!r} (expected one of {', '.join(SUPPORTED_TYPES)})")
        mimic: tuple[str, float, float] | None = None
        mimic_el = element.find("mimic")
        if mimic_el is not None and kind in MOVABLE_TYPES:  # on a fixed joint it means nothing (as in ROS)
            followed = mimic_el.get("joint")
            if not followed:
                raise UrdfError(f"{where}: <mimic> needs joint=...")
            mimic = (
                followed,
                _float(mimic_el, "multiplier", 1.0, f"{where} mimic"),
                _float(mimic_el, "offset", 0.0, f"{where} mimic"),
            )
        parent_el, child_el = element.find("parent"), element.find("child")
        if parent_el is None or child_el is None:
            raise UrdfError(f"{where}: expected <parent link=...> and <child link=...>")
        parent, child = parent_el.get("link"), child_el.get("link")
        for role, link in (("parent", parent), ("child", child)):
            if link not in link_names:
                raise UrdfError(f"{where}: {role} link {link!r} is not a <link> of the file")
        assert parent is not None and child is not None  # both are links of the file
        if child in children:
            raise _two_parents(robot, next(j for j in joints if j.child == child), name, parent, child, where)
        children.add(child)
        origin = element.find("origin")
        xyz = _floats(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0), f"{where} origin xyz")
        rpy = _floats(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0), f"{where} origin rpy")
        axis_el = element.find("axis")
        axis = _floats(axis_el.get("xyz") if axis_el is not None else None, (1.0, 0.0, 0.0), f"{where} axis")
        norm = math.sqrt(sum(a * a for a in axis))
        if kind in MOVABLE_TYPES and norm < 1e-12:
            raise UrdfError(f"{where}: axis must be non-zero, got {axis}")
        if norm > 0:
            axis = (axis[0] / norm, axis[1] / norm, axis[2] / norm)
        lower, upper, effort, velocity = _limits(element, kind, where)
        joints.append(UrdfJoint(name, kind, parent, child, xyz, rpy, axis, lower, upper, effort, velocity, mimic))
    return joints


def _two_parents(robot: ET.Element, first: UrdfJoint, name: str, parent: str, child: str, where: str) -> UrdfError:
    """The error for a link that two joints hold, with the way out when one of them hangs from a
    root of its own (a robot mounted by a second root)."""
    held = {c.get("link") for c in robot.findall("joint/child")}
    own_root = next((p for p in (first.parent, parent) if p not in held), None)
    mount = parent if own_root == first.parent else first.parent
    hint = (
        (
            f"; {own_root!r} is a root of the file already: mount the robot by it (a joint from "
            f"{mount!r} to {own_root!r}), or leave {own_root!r} and its joint out"
        )
        if own_root
        else ""
    )
    return UrdfError(
        f"{where}: link {child!r} has two parent joints, {first.name!r} (from {first.parent!r}) and "
        f"{name!r} (from {parent!r}){hint}"
    )


def _limits(element: ET.Element, kind: str, where: str) -> tuple[float, float, float, float]:
    """A joint's (lower, upper, effort, velocity): -inf/+inf where the URDF gives none."""
    lower, upper, effort, velocity = -math.inf, math.inf, math.inf, math.inf
    limit = element.find("limit")
    if limit is not None:
        effort = _float(limit, "effort", math.inf, f"{where} limit")
        velocity = _float(limit, "velocity", math.inf, f"{where} limit")
        if effort <= 0.0:  # URDF convention: 0 effort means "not given"
            effort = math.inf
        if kind in ("revolute", "prismatic"):
            lower = _float(limit, "lower", 0.0, f"{where} limit")
            upper = _float(limit, "upper", 0.0, f"{where} limit")
            if lower > upper:
                raise UrdfError(f"{where}: limit lower {lower} > upper {upper}")
    elif kind in ("revolute", "prismatic"):
        raise UrdfError(f"{where}: a {kind} joint needs a <limit> element")
    return lower, upper, effort, velocity
