"""URDF reading without a physics engine: structure, limits, masses, and the text DART loads.

``read_urdf(path)`` parses a URDF with :mod:`xml.etree` only, so a component can declare its
variables (joint and link counts, names) cheaply, before DART is imported. The same parsed model
then produces the URDF text given to DART (``dart_urdf_text``): locked joints welded at their
initial position, massless frame links (tool frames) left out of the multibody.

Conventions (URDF): a joint's ``origin`` places its frame in the parent link frame, rpy is
R = Rz(yaw) Ry(pitch) Rx(roll); ``axis`` is in the joint frame. Units: m, rad, kg, kg m^2, N m.

Supported joint types: revolute, continuous, prismatic (one degree of freedom each) and fixed;
a movable joint may ``<mimic>`` another (q = multiplier q_other + offset). The root link is the
free-floating base. ``UrdfError`` says what is wrong and where.

Files as ROS packages ship them: a ``.xacro`` is expanded first (``$(find NAME)`` resolved), and
every mesh ``filename`` (``package://NAME/...``, ``file://``, relative) is resolved
(:mod:`components.robots.packages`) and rewritten as an absolute path in the parsed tree, so the
text handed to DART and Pinocchio (``UrdfModel.text``, ``dart_urdf_text``) needs no package
lookup of its own. A mesh not found, an inertia that is not positive definite or breaks the
triangle inequality (ixx <= iyy + izz, ...) are errors naming the link.
"""

from __future__ import annotations

import hashlib
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from components.robots.packages import PackageError, process_xacro, resolve_uri
from components.rotations import exp_so3, matrix_to_rpy, rpy_to_matrix

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


@dataclass
class UrdfModel:
    """A parsed URDF. ``links`` and ``joints`` are in file order; ``movable_joints`` are the
    names of the non-fixed joints in file order (the layout of q, qd and tau)."""

    path: Path
    name: str
    links: list[UrdfLink]
    joints: list[UrdfJoint]
    root: str
    tree: ET.ElementTree = field(repr=False)

    @property
    def link_names(self) -> list[str]:
        return [link.name for link in self.links]

    @property
    def movable_joints(self) -> list[str]:
        return [j.name for j in self.joints if j.movable]

    def joint(self, name: str) -> UrdfJoint:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)

    def link(self, name: str) -> UrdfLink:
        for link in self.links:
            if link.name == name:
                return link
        raise KeyError(name)

    @property
    def text(self) -> str:
        """The URDF as parsed: xacro expanded, mesh file names absolute paths."""
        return ET.tostring(self.tree.getroot(), encoding="unicode")

    @property
    def mimics(self) -> dict[str, tuple[str, float, float]]:
        """Mimic joints: name -> (joint followed, multiplier, offset)."""
        return {j.name: j.mimic for j in self.joints if j.mimic is not None}

    def notes(self) -> list[str]:
        """What loads but is suspect: a movable joint whose child, with everything welded to it
        (fixed joints), has no mass (an infinite acceleration under any torque)."""
        by_parent: dict[str, list[UrdfJoint]] = {}
        for j in self.joints:
            by_parent.setdefault(j.parent, []).append(j)

        def welded_mass(link: str) -> float:
            return self.link(link).mass + sum(
                welded_mass(j.child) for j in by_parent.get(link, ()) if j.type == "fixed"
            )

        notes = []
        for j in self.joints:
            if j.movable and j.mimic is None and welded_mass(j.child) <= 0.0:
                notes.append(
                    f"{self.path.name}: link {j.child!r} has no mass (nor anything welded to it), "
                    f"but joint {j.name!r} moves it: a torque on it has nothing to accelerate"
                )
        return notes

    def frame_links(self) -> dict[str, UrdfJoint]:
        """Links that are pure frames: no mass, no collision, no children, attached by a fixed
        joint (tool frames). They are left out of the DART multibody; maps link -> its joint."""
        parents = {j.parent for j in self.joints}
        by_child = {j.child: j for j in self.joints}
        frames = {}
        for link in self.links:
            joint = by_child.get(link.name)
            if (
                joint is not None
                and joint.type == "fixed"
                and link.mass == 0.0
                and not link.has_collision
                and link.name not in parents
            ):
                frames[link.name] = joint
        return frames


def _floats(text: str | None, n: int, default: tuple[float, ...], where: str) -> tuple[float, ...]:
    if text is None:
        return default
    parts = text.split()
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise UrdfError(f"{where}: expected {n} numbers, got {text!r}") from None
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise UrdfError(f"{where}: expected {n} finite numbers, got {text!r}")
    return values


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


def _resolve_meshes(robot: ET.Element, path: Path, packages) -> None:
    """Every mesh file name made an absolute path; UrdfError naming the link and the URI."""
    for link in robot.findall("link"):
        for kind in ("visual", "collision"):
            for element in link.findall(kind):
                for mesh in element.iter("mesh"):
                    uri = mesh.get("filename")
                    if not uri:
                        raise UrdfError(f"{path.name}: link {link.get('name')!r} {kind} mesh has no filename")
                    try:
                        mesh.set("filename", str(resolve_uri(uri, path.parent, packages)))
                    except PackageError as e:
                        raise UrdfError(f"{path.name}: link {link.get('name')!r} {kind} mesh {e}") from None


def _source(path: Path, packages) -> str | bytes:
    if not path.is_file():
        raise UrdfError(f"URDF file {path} not found")
    try:
        if path.suffix == ".xacro":
            return process_xacro(path, packages)
        return path.read_bytes()  # bytes: the XML declaration's encoding applies
    except (PackageError, ValueError) as e:
        raise UrdfError(str(e)) from None


def source_text(path: str | Path, packages=None) -> str:
    """The URDF as its author wrote it: a ``.xacro`` expanded, mesh URIs as written (``package://``
    kept), what ROS's ``robot_description`` carries; UrdfError when it cannot be read."""
    text = _source(Path(path), packages)
    return text.decode("utf-8") if isinstance(text, bytes) else text


def read_urdf(path: str | Path, packages=None) -> UrdfModel:
    """Parse and check a URDF (or .xacro) file: tree of links, supported joints, positive base
    mass, physical inertias, mesh files found. ``packages``: name -> directory (``run.packages``).
    Parsed once per process: the check, the declaration and the setup of every component in the
    process share the model (read-only), until the file's text changes."""
    path = Path(path)
    key = (path.resolve(), _digest(path), tuple(sorted((str(k), str(v)) for k, v in (packages or {}).items())))
    model = _parsed.get(key)
    if model is None:
        model = _parsed[key] = _parse(path, packages)
    return model


_parsed: dict[tuple, UrdfModel] = {}  # read_urdf's: (resolved path, text's digest, packages) -> model


def _digest(path: Path) -> bytes:
    """The file's text digest (a xacro's top file: its includes are taken as unchanged for the process)."""
    try:
        return hashlib.blake2b(path.read_bytes(), digest_size=16).digest()
    except OSError:
        raise UrdfError(f"URDF file {path} not found") from None


def _parse(path: Path, packages) -> UrdfModel:
    text = _source(path, packages)
    try:
        tree = ET.ElementTree(ET.fromstring(text))
    except ET.ParseError as e:
        raise UrdfError(f"{path} is not valid XML: {e}") from None
    robot = tree.getroot()
    if robot.tag != "robot":
        raise UrdfError(f"{path}: expected a <robot> root element, got <{robot.tag}>")
    links = _read_links(robot, path)
    joints = _read_joints(robot, path, {link.name for link in links})
    _check_mimics(joints, path)
    root = _root_link(links, joints, path)
    _resolve_meshes(robot, path, packages)
    return UrdfModel(path, robot.get("name") or path.stem.removesuffix(".urdf"), links, joints, root, tree)


def _read_links(robot: ET.Element, path: Path) -> list[UrdfLink]:
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
                com = _floats(origin.get("xyz"), 3, com, f"{where} inertial origin xyz")
                rpy = _floats(origin.get("rpy"), 3, rpy, f"{where} inertial origin rpy")
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


def _read_joints(robot: ET.Element, path: Path, link_names: set[str]) -> list[UrdfJoint]:
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
        mimic = None
        mimic_el = element.find("mimic")
        if mimic_el is not None and kind in MOVABLE_TYPES:  # on a fixed joint it means nothing (as in ROS)
            if not mimic_el.get("joint"):
                raise UrdfError(f"{where}: <mimic> needs joint=...")
            mimic = (
                mimic_el.get("joint"),
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
        if child in children:
            raise _two_parents(robot, next(j for j in joints if j.child == child), name, parent, child, where)
        children.add(child)
        origin = element.find("origin")
        xyz = _floats(origin.get("xyz") if origin is not None else None, 3, (0.0, 0.0, 0.0), f"{where} origin xyz")
        rpy = _floats(origin.get("rpy") if origin is not None else None, 3, (0.0, 0.0, 0.0), f"{where} origin rpy")
        axis_el = element.find("axis")
        axis = _floats(axis_el.get("xyz") if axis_el is not None else None, 3, (1.0, 0.0, 0.0), f"{where} axis")
        norm = math.sqrt(sum(a * a for a in axis))
        if kind in MOVABLE_TYPES and norm < 1e-12:
            raise UrdfError(f"{where}: axis must be non-zero, got {axis}")
        if norm > 0:
            axis = tuple(a / norm for a in axis)
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


def _check_mimics(joints: list[UrdfJoint], path: Path) -> None:
    """Each mimic joint follows a movable joint of the file that is not a mimic itself."""
    by_name = {j.name: j for j in joints}
    for j in joints:
        if j.mimic is None:
            continue
        followed = by_name.get(j.mimic[0])
        if followed is None or not followed.movable:
            raise UrdfError(
                f"{path.name}: joint {j.name!r} mimics {j.mimic[0]!r}, which is not a movable joint of the file"
            )
        if followed.mimic is not None:
            raise UrdfError(
                f"{path.name}: joint {j.name!r} mimics {followed.name!r}, itself a mimic joint "
                f"(make both follow {followed.mimic[0]!r})"
            )
        if not all(math.isfinite(v) for v in j.mimic[1:]):
            raise UrdfError(f"{path.name}: joint {j.name!r}: mimic multiplier and offset must be finite")


def _root_link(links: list[UrdfLink], joints: list[UrdfJoint], path: Path) -> str:
    """The one root link (the free-floating base, with a mass) from which every link hangs."""
    children = {j.child for j in joints}
    link_names = {link.name for link in links}
    roots = [link.name for link in links if link.name not in children]
    if len(roots) != 1:
        raise UrdfError(
            f"{path.name}: expected one root link (the free-floating base), got {roots or 'none (a cycle)'}"
        )
    root = roots[0]
    # every link reachable from the root (no cycles, nothing detached)
    by_parent: dict[str, list[str]] = {}
    for j in joints:
        by_parent.setdefault(j.parent, []).append(j.child)
    seen, stack = set(), [root]
    while stack:
        link = stack.pop()
        if link in seen:
            raise UrdfError(f"{path.name}: the links do not form a tree (cycle at {link!r})")
        seen.add(link)
        stack.extend(by_parent.get(link, []))
    if seen != link_names:
        raise UrdfError(f"{path.name}: links not connected to the root {root!r}: {sorted(link_names - seen)}")
    if root == "world":
        raise UrdfError(f"{path.name}: the root link is the free-floating base; remove the 'world' link and its joint")
    root_link = next(link for link in links if link.name == root)
    if root_link.mass <= 0.0:
        raise UrdfError(f"{path.name}: the base link {root!r} needs a positive mass, got {root_link.mass} kg")
    return root


def dart_urdf_text(model: UrdfModel, locked: dict[str, float]) -> str:
    """The URDF text DART loads: joints in ``locked`` (name -> position) become fixed joints at
    that position, and frame links (see ``UrdfModel.frame_links``) are left out."""
    tree = ET.ElementTree(ET.fromstring(ET.tostring(model.tree.getroot())))
    robot = tree.getroot()
    frames = model.frame_links()
    for element in list(robot.findall("joint")):
        name = element.get("name")
        if element.find("child").get("link") in frames:
            robot.remove(element)
            continue
        if name not in locked:
            continue
        joint = model.joint(name)
        R = rpy_to_matrix(joint.rpy)
        p = np.array(joint.xyz, dtype=float)
        q0 = float(locked[name])
        if joint.type == "prismatic":
            p = p + R @ (np.array(joint.axis) * q0)
        else:
            R = R @ exp_so3(np.array(joint.axis) * q0)
        element.set("type", "fixed")
        for tag in ("origin", "axis", "limit", "dynamics", "safety_controller", "calibration"):
            for child in element.findall(tag):
                element.remove(child)
        ET.SubElement(
            element,
            "origin",
            xyz=" ".join(repr(float(v)) for v in p),
            rpy=" ".join(repr(float(v)) for v in matrix_to_rpy(R)),
        )
    for element in list(robot.findall("link")):
        if element.get("name") in frames:
            robot.remove(element)
    return ET.tostring(robot, encoding="unicode")
