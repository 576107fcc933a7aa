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
triangle inequality (ixx <= iyy + izz, ...) are errors naming the link. The link and joint
elements are read, and UrdfError defined, in :mod:`components.robots.urdf_elements`.
"""

from __future__ import annotations

import hashlib
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from components.robots.packages import PackageError, process_xacro, resolve_uri
from components.robots.urdf_elements import UrdfError, UrdfJoint, UrdfLink, read_joints, read_links
from components.rotations import exp_so3, matrix_to_rpy, rpy_to_matrix


@dataclass
class UrdfModel:
    """A parsed URDF. ``links`` and ``joints`` are in file order; ``movable_joints`` are the
    names of the non-fixed joints in file order (the layout of q, qd and tau)."""

    path: Path
    name: str
    links: list[UrdfLink]
    joints: list[UrdfJoint]
    root: str
    tree: ET.ElementTree[ET.Element] = field(repr=False)

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
        tree: ET.ElementTree[ET.Element] = ET.ElementTree(ET.fromstring(text))
    except ET.ParseError as e:
        raise UrdfError(f"{path} is not valid XML: {e}") from None
    robot = tree.getroot()
    if robot.tag != "robot":
        raise UrdfError(f"{path}: expected a <robot> root element, got <{robot.tag}>")
    links = read_links(robot, path)
    joints = read_joints(robot, path, {link.name for link in links})
    _check_mimics(joints, path)
    root = _root_link(links, joints, path)
    _resolve_meshes(robot, path, packages)
    return UrdfModel(path, robot.get("name") or path.stem.removesuffix(".urdf"), links, joints, root, tree)


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
    robot = ET.fromstring(ET.tostring(model.tree.getroot()))
    frames = model.frame_links()
    for element in list(robot.findall("joint")):
        name = element.get("name")
        child = element.find("child")
        assert child is not None  # read_joints checked every joint has one
        if child.get("link") in frames:
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
