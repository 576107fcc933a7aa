"""What the viewer needs of a robot: its URDF visuals and its forward kinematics (Pinocchio).

``read_geometry(path)`` reads the URDF with the parser the dynamics uses
(:func:`components.robots.urdf.read_urdf`: same checks, same link and joint layout) and adds
the links' ``<visual>`` elements (box, cylinder, sphere, mesh) with their colours, and their
``<collision>`` shapes (drawn instead of a visual mesh that cannot be read). Mesh file names are
those the parser resolved (``package://`` included): absolute paths of files that exist.
``mesh_arrays`` reads any mesh trimesh reads (``.dae`` through pycollada, ``.obj``, ``.stl``, ``.glb``,
``.ply`` ...) into vertex and triangle arrays for Rerun.
``Kinematics`` turns recorded base poses and joint positions into the pose of every link, for a
whole batch of rows at once: the base is a free flyer (``position`` = base link origin in W,
``orientation`` = q_W_base [x, y, z, w]) and ``q`` follows the movable joints in URDF file order,
as the ``dynamics.dart`` outputs do. Units: m, rad.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from components.robots.urdf import read_urdf

DEFAULT_COLOR = (150, 150, 155, 255)


@dataclass(frozen=True)
class Visual:
    """One ``<visual>`` of a link: ``kind`` box | cylinder | sphere | mesh, placed by ``xyz``/``rpy``
    in the link frame. ``size``: box (x, y, z) full lengths; cylinder (radius, length) along its z;
    sphere (radius,); mesh (scale x, y, z) with ``mesh`` the file, resolved when it exists."""

    link: str
    kind: str
    size: tuple[float, ...]
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    color: tuple[int, int, int, int]
    mesh: Path | None = None


@dataclass
class Geometry:
    """A URDF as the viewer sees it: link names and CoMs (link frame) in file order, movable
    joints in file order, visuals."""

    path: Path
    name: str
    links: list[str]
    coms: np.ndarray  # (n_links, 3), m, link frame
    joints: list[str]  # movable joints, file order (layout of q and tau)
    visuals: list[Visual] = field(default_factory=list)
    collisions: list[Visual] = field(default_factory=list)
    text: str = ""  # the URDF as parsed (xacro expanded, mesh paths absolute)


def _floats(text: str | None, n: int, default: tuple[float, ...]) -> tuple[float, ...]:
    if text is None:
        return default
    values = tuple(float(v) for v in text.split())
    if len(values) != n:
        raise ValueError(f"expected {n} numbers, got {text!r}")
    return values


def _triple(text: str | None, default: tuple[float, float, float]) -> tuple[float, float, float]:
    x, y, z = _floats(text, 3, default)
    return x, y, z


def _color(element: ET.Element | None) -> tuple[int, int, int, int] | None:
    color = element.find("color") if element is not None else None
    if color is None or color.get("rgba") is None:
        return None
    r, g, b, a = (int(round(255 * min(max(c, 0.0), 1.0))) for c in _floats(color.get("rgba"), 4, (0.6, 0.6, 0.6, 1.0)))
    return r, g, b, a


def mesh_arrays(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Vertices (n, 3), triangles (m, 3), vertex normals (n, 3) and vertex colours (n, 4, uint8;
    None when the file has none) of a mesh file, every part of a scene merged (trimesh; COLLADA
    through pycollada). Raises whatever trimesh raises for a file it cannot read."""
    import trimesh
    from trimesh.visual.color import ColorVisuals
    from trimesh.visual.texture import TextureVisuals

    mesh = trimesh.load(str(path), force="mesh")
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"{path.name}: no triangles")
    colors = None
    try:
        visual = mesh.visual
        if isinstance(visual, TextureVisuals) and visual.kind is not None:
            visual = visual.to_color()  # a texture baked into vertex colours
        # face colours (a merged scene's materials) reach the vertices averaged over their faces:
        # exact where, as there, each part has vertices of its own
        if isinstance(visual, ColorVisuals) and visual.kind in ("vertex", "face"):
            colors = np.asarray(visual.vertex_colors, dtype=np.uint8)
            if colors.shape != (len(mesh.vertices), 4):
                colors = None
    except Exception:  # a texture trimesh cannot bake into colours: the URDF's colour instead
        colors = None
    return (
        np.asarray(mesh.vertices, dtype=np.float32),
        np.asarray(mesh.faces, dtype=np.uint32),
        np.asarray(mesh.vertex_normals, dtype=np.float32),
        colors,
    )


def _shape(name: str, element: ET.Element, color) -> Visual | None:
    origin = element.find("origin")
    xyz = _triple(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0))
    rpy = _triple(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0))
    geometry = element.find("geometry")
    shape = geometry[0] if geometry is not None and len(geometry) else None
    if shape is None:
        return None
    if shape.tag == "box":
        return Visual(name, "box", _floats(shape.get("size"), 3, (0.1, 0.1, 0.1)), xyz, rpy, color)
    if shape.tag == "cylinder":
        return Visual(
            name, "cylinder", (float(shape.get("radius", 0.05)), float(shape.get("length", 0.1))), xyz, rpy, color
        )
    if shape.tag == "sphere":
        return Visual(name, "sphere", (float(shape.get("radius", 0.05)),), xyz, rpy, color)
    filename = shape.get("filename")
    if shape.tag == "mesh" and filename:
        mesh = Path(filename)  # resolved by read_urdf: an absolute path that exists
        return Visual(
            name,
            "mesh",
            _floats(shape.get("scale"), 3, (1.0, 1.0, 1.0)),
            xyz,
            rpy,
            color,
            mesh if mesh.is_file() else None,
        )
    return None


def read_geometry(path: str | Path, packages=None) -> Geometry:
    """Links, CoMs, movable joints (from :func:`read_urdf`), visuals and collision shapes of a
    URDF (or .xacro); ValueError (``UrdfError``) naming the file when it is missing or broken.
    ``packages``: ``run.packages`` (name -> directory) for ``package://`` URIs."""
    model = read_urdf(path, packages)
    root = model.tree.getroot()
    assert root is not None, "read_urdf parsed a tree"
    materials = {m.get("name"): _color(m) for m in root.findall("material")}
    visuals, collisions = [], []
    for link in root.findall("link"):
        name = link.get("name")
        assert name, "read_urdf refuses a link without a name"
        for collision in link.findall("collision"):
            shape = _shape(name, collision, DEFAULT_COLOR)
            if shape is not None:
                collisions.append(shape)
        for visual in link.findall("visual"):
            material = visual.find("material")
            color = _color(material) or (materials.get(material.get("name")) if material is not None else None)
            shape = _shape(name, visual, color or DEFAULT_COLOR)
            if shape is not None:
                visuals.append(shape)
    return Geometry(
        path=model.path,
        name=model.name,
        links=model.link_names,
        coms=np.array([link.com for link in model.links], dtype=float).reshape(-1, 3),
        joints=model.movable_joints,
        visuals=visuals,
        collisions=collisions,
        text=model.text,
    )


def normalized_quaternions(q: np.ndarray) -> np.ndarray:
    """Rows of [x, y, z, w] normalized; an all-zero row (nothing recorded yet) becomes identity."""
    q = np.array(q, dtype=float, copy=True)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    zero = norm[..., 0] < 1e-12
    q[zero] = (0.0, 0.0, 0.0, 1.0)
    norm[zero] = 1.0
    return q / norm


class Kinematics:
    """Forward kinematics of a free-floating URDF with Pinocchio: link poses in W for batches of rows."""

    def __init__(self, geometry: Geometry):
        import pinocchio as pin

        self._pin = pin
        self.geometry = geometry
        if geometry.text:  # as parsed: xacro expanded, package URIs resolved
            self.model = pin.buildModelFromXML(geometry.text, pin.JointModelFreeFlyer())
        else:
            self.model = pin.buildModelFromUrdf(str(geometry.path), pin.JointModelFreeFlyer())
        self.data = self.model.createData()
        self.frames = [self.model.getFrameId(link, pin.FrameType.BODY) for link in geometry.links]
        # where each URDF movable joint sits in Pinocchio's configuration vector (nq 2: cos, sin)
        self.slots = []
        for name in geometry.joints:
            joint = self.model.joints[self.model.getJointId(name)]
            self.slots.append((joint.idx_q, joint.nq))

    @property
    def n_joints(self) -> int:
        return len(self.slots)

    def configuration(self, position, orientation, q) -> np.ndarray:
        """Pinocchio configuration of one row: base position, q_W_base [x, y, z, w], joints."""
        config = self._pin.neutral(self.model)
        config[:3] = position
        config[3:7] = orientation
        for (index, nq), value in zip(self.slots, q):
            if nq == 2:
                config[index], config[index + 1] = np.cos(value), np.sin(value)
            else:
                config[index] = value
        return config

    def link_poses(self, position: np.ndarray, orientation: np.ndarray, q: np.ndarray):
        """Rows (n, 3), (n, 4), (n, n_joints) -> link origins (n, L, 3) and rotations (n, L, 3, 3) in W."""
        pin = self._pin
        n, L = len(position), len(self.frames)
        orientation = normalized_quaternions(orientation)
        translations = np.empty((n, L, 3))
        rotations = np.empty((n, L, 3, 3))
        for i in range(n):
            pin.framesForwardKinematics(self.model, self.data, self.configuration(position[i], orientation[i], q[i]))
            for j, frame in enumerate(self.frames):
                placement = self.data.oMf[frame]
                translations[i, j] = placement.translation
                rotations[i, j] = placement.rotation
        return translations, rotations
