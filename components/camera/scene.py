"""What a camera sees of the bodies: their URDF visuals as triangle meshes in their link frames,
and the link poses from a body's base pose and joint positions (the dynamics' outputs).

Plain functions and a class, no bus and no I/O beyond reading the URDFs and their mesh files
(:mod:`components.viewer.robot`, the meshes the viewer loads). Boxes, cylinders (64 sides) and
spheres (an icosphere of 1280 triangles) are tessellated here; a mesh visual is read with trimesh,
its ``scale`` applied. A visual whose mesh cannot be read is replaced by its link's collision
shapes, as the viewer does. Colour: a mesh file's texture (its base colour image and texture
coordinates: .obj with .mtl, .glb/.gltf, .dae) or its face or vertex colours when it has them,
else the URDF's colour. Normals are per triangle (flat shading). Units: m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from components.rotations import quat_to_matrix, rpy_to_matrix
from components.viewer.robot import Geometry, Kinematics, Visual


@dataclass(frozen=True)
class VisualMesh:
    """One visual's triangles in its link's frame: ``vertices`` (3 per triangle, (3m, 3)), their
    ``normals`` (the triangle's) and ``colours`` (r, g, b in 0..1), or ``uv`` and a ``texture``
    ((h, w, 3) uint8, row 0 the top); ``link`` its index in the body's links."""

    link: int
    vertices: np.ndarray
    normals: np.ndarray
    colours: np.ndarray
    uv: np.ndarray | None = None
    texture: np.ndarray | None = None


def transform(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The 4x4 homogeneous transform of rotation ``R`` and translation ``p``."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def pose_matrix(position, orientation) -> np.ndarray:
    """4x4 transform of a position (m) and a quaternion [x, y, z, w] (normalized here)."""
    return transform(quat_to_matrix(np.asarray(orientation, dtype=np.float64)), np.asarray(position, dtype=np.float64))


def _shape_trimesh(visual: Visual):
    import trimesh

    if visual.kind == "box":
        return trimesh.creation.box(extents=visual.size)
    if visual.kind == "cylinder":
        return trimesh.creation.cylinder(radius=visual.size[0], height=visual.size[1], sections=64)
    if visual.kind == "sphere":
        return trimesh.creation.icosphere(subdivisions=3, radius=visual.size[0])
    if visual.kind == "mesh":
        if visual.mesh is None:
            raise ValueError("mesh file not found")
        mesh = trimesh.load(str(visual.mesh), force="mesh")
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            raise ValueError(f"{visual.mesh.name}: no triangles")
        mesh.vertices = np.asarray(mesh.vertices, dtype=np.float64) * np.asarray(visual.size)
        return mesh
    raise ValueError(f"unknown visual kind {visual.kind!r}")


def _appearance(mesh, colour: np.ndarray):
    """(colours (3m, 3), uv (3m, 2) or None, texture or None) per triangle corner of ``mesh``: its
    texture, else its face or vertex colours, else ``colour`` (r, g, b in 0..1)."""
    corners = mesh.faces.ravel()
    visual = mesh.visual
    try:
        if (
            visual.kind == "texture"
            and getattr(visual, "uv", None) is not None
            and len(visual.uv) == len(mesh.vertices)
        ):
            material = visual.material
            image = getattr(material, "image", None) or getattr(material, "baseColorTexture", None)
            if image is not None:
                texture = np.asarray(image.convert("RGB"), dtype=np.uint8)
                return np.tile(colour, (len(corners), 1)), np.asarray(visual.uv, dtype=np.float64)[corners], texture
        if visual.kind == "face":
            return np.repeat(np.asarray(visual.face_colors, dtype=np.float64)[:, :3] / 255.0, 3, axis=0), None, None
        if visual.kind == "vertex":
            return np.asarray(visual.vertex_colors, dtype=np.float64)[corners, :3] / 255.0, None, None
    except Exception:  # a material trimesh cannot read: the URDF's colour instead
        pass
    return np.tile(colour, (len(corners), 1)), None, None


def visual_meshes(geometry: Geometry) -> tuple[list[VisualMesh], list[str]]:
    """Every visual of a body as a :class:`VisualMesh`, and a line per visual that could not be
    made (and what replaced it)."""
    meshes, notes = [], []
    for visual in geometry.visuals:
        try:
            shapes = [(_shape_trimesh(visual), visual)]
        except Exception as e:  # trimesh's and pycollada's own exceptions for a file they cannot read
            shapes = []
            for collision in (c for c in geometry.collisions if c.link == visual.link):
                try:
                    shapes.append((_shape_trimesh(collision), collision))
                except Exception:
                    continue
            notes.append(
                f"{geometry.name}: visual of link {visual.link} cannot be read ({e}); "
                f"{'its collision shapes drawn instead' if shapes else 'not drawn'}"
            )
        for mesh, placed in shapes:
            T = transform(rpy_to_matrix(placed.rpy), np.asarray(placed.xyz, dtype=np.float64))
            corners = mesh.vertices[mesh.faces.ravel()]  # 3 per triangle
            corners = corners @ T[:3, :3].T + T[:3, 3]
            normals = np.repeat(np.asarray(mesh.face_normals) @ T[:3, :3].T, 3, axis=0)
            colours, uv, texture = _appearance(mesh, np.array(visual.color[:3], dtype=np.float64) / 255.0)
            meshes.append(VisualMesh(geometry.links.index(visual.link), corners, normals, colours, uv, texture))
    return meshes, notes


class BodyPoses:
    """A body's link poses in W (4x4 each, link order of the URDF) from its base pose and joints."""

    def __init__(self, geometry: Geometry):
        self.kinematics = Kinematics(geometry)

    def link_transforms(self, position: np.ndarray, orientation: np.ndarray, q: np.ndarray) -> np.ndarray:
        """(L, 4, 4): T_W_link for every link, base ``position`` (m, W), ``orientation``
        (q_W_base [x, y, z, w]) and joint positions ``q`` (URDF order of the movable joints)."""
        translations, rotations = self.kinematics.link_poses(
            np.asarray(position, dtype=np.float64)[None],
            np.asarray(orientation, dtype=np.float64)[None],
            np.asarray(q, dtype=np.float64)[None],
        )
        T = np.tile(np.eye(4), (translations.shape[1], 1, 1))
        T[:, :3, :3], T[:, :3, 3] = rotations[0], translations[0]
        return T
