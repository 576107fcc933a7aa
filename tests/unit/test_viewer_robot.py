"""Viewer robot geometry and forward kinematics (Pinocchio) against a hand-written URDF chain in numpy."""

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from components.viewer.robot import Kinematics, normalized_quaternions, read_geometry

ROOT = Path(__file__).resolve().parents[2]

CHAIN = """<?xml version="1.0"?>
<robot name="chain">
  <material name="red"><color rgba="1 0 0 1"/></material>
  <link name="base"><inertial><origin xyz="0.1 0 0"/><mass value="10"/>
    <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
    <visual><geometry><box size="0.2 0.4 0.6"/></geometry><material name="red"/></visual></link>
  <joint name="spin" type="continuous"><parent link="base"/><child link="a"/>
    <origin xyz="0 0 0.3" rpy="0.3 -0.2 0.5"/><axis xyz="0 0 1"/></joint>
  <link name="a"><inertial><origin xyz="0 0 0.1"/><mass value="1"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
    <visual><origin xyz="0 0 0.1" rpy="1.5707963 0 0"/><geometry><cylinder radius="0.03" length="0.2"/></geometry>
      <material name="inline"><color rgba="0 0.5 1 1"/></material></visual></link>
  <joint name="slide" type="prismatic"><parent link="a"/><child link="b"/>
    <origin xyz="0 0.1 0.2" rpy="0 0.4 0"/><axis xyz="0.6 0 0.8"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <link name="b"><inertial><origin xyz="0 0 0"/><mass value="1"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
    <visual><geometry><sphere radius="0.05"/></geometry></visual></link>
  <joint name="bend" type="revolute"><parent link="b"/><child link="c"/>
    <origin xyz="0.2 0 0" rpy="0 0 -0.7"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <link name="c"><inertial><origin xyz="0 0 0"/><mass value="1"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="tool_joint" type="fixed"><parent link="c"/><child link="tool"/><origin xyz="0 0 0.15" rpy="0 0 1"/></joint>
  <link name="tool"/>
</robot>
"""


def rot(axis, angle):
    """Rodrigues' formula."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def rpy(r, p, y):
    return rot([0, 0, 1], y) @ rot([0, 1, 0], p) @ rot([1, 0, 0], r)


def reference_poses(path, p_base, q_base, joint_values):
    """Link poses by walking the URDF tree with 4x4 matrices: T_child = T_parent T_origin T_motion."""
    root = ET.parse(path).getroot()
    x, y, z, w = q_base
    R0 = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    links = [link.get("name") for link in root.findall("link")]
    children = {j.find("child").get("link") for j in root.findall("joint")}
    base = next(name for name in links if name not in children)
    T = {base: np.block([[R0, np.reshape(p_base, (3, 1))], [np.zeros((1, 3)), np.ones((1, 1))]])}
    pending = root.findall("joint")
    while pending:
        for j in list(pending):
            parent, child = j.find("parent").get("link"), j.find("child").get("link")
            if parent not in T:
                continue
            origin = j.find("origin")
            xyz = [float(v) for v in origin.get("xyz", "0 0 0").split()]
            angles = [float(v) for v in origin.get("rpy", "0 0 0").split()]
            A = np.eye(4)
            A[:3, :3], A[:3, 3] = rpy(*angles), xyz
            M = np.eye(4)
            axis_el = j.find("axis")
            axis = [float(v) for v in axis_el.get("xyz").split()] if axis_el is not None else [1, 0, 0]
            value = joint_values.get(j.get("name"), 0.0)
            if j.get("type") in ("revolute", "continuous"):
                M[:3, :3] = rot(axis, value)
            elif j.get("type") == "prismatic":
                M[:3, 3] = value * np.asarray(axis) / np.linalg.norm(axis)
            T[child] = T[parent] @ A @ M
            pending.remove(j)
    return {name: (T[name][:3, 3], T[name][:3, :3]) for name in links}


def test_geometry_reads_links_joints_visuals_and_colours(tmp_path):
    path = tmp_path / "chain.urdf"
    path.write_text(CHAIN)
    g = read_geometry(path)
    assert g.links == ["base", "a", "b", "c", "tool"]
    assert g.joints == ["spin", "slide", "bend"]  # movable joints, file order
    assert np.allclose(g.coms[0], [0.1, 0, 0]) and np.allclose(g.coms[4], 0)
    kinds = [(v.link, v.kind, v.size) for v in g.visuals]
    assert kinds == [("base", "box", (0.2, 0.4, 0.6)), ("a", "cylinder", (0.03, 0.2)), ("b", "sphere", (0.05,))]
    assert g.visuals[0].color == (255, 0, 0, 255)  # named material at the top level
    assert g.visuals[1].color == (0, 128, 255, 255)  # inline colour


def test_humanoid_geometry_matches_the_dynamics_layout():
    g = read_geometry(ROOT / "models" / "humanoid_torso.urdf")
    assert len(g.links) == 17 and len(g.joints) == 14
    assert g.joints[0] == "arm_left_1_joint" and g.links[0] == "torso"
    assert {v.kind for v in g.visuals} == {"box", "cylinder", "sphere"}


@pytest.mark.parametrize("urdf", ["chain", "humanoid_torso.urdf", "servicer.urdf"])
def test_link_poses_match_a_numpy_walk_of_the_urdf(tmp_path, urdf):
    if urdf == "chain":
        path = tmp_path / "chain.urdf"
        path.write_text(CHAIN)
    else:
        path = ROOT / "models" / urdf
    g = read_geometry(path)
    kin = Kinematics(g)
    rng = np.random.default_rng(7)
    n = 5
    position = rng.normal(size=(n, 3))
    orientation = rng.normal(size=(n, 4))
    orientation *= 3.0  # not normalized: the viewer normalizes
    q = rng.uniform(-1.5, 1.5, size=(n, len(g.joints)))
    translations, rotations = kin.link_poses(position, orientation, q)
    for i in range(n):
        unit = orientation[i] / np.linalg.norm(orientation[i])
        reference = reference_poses(path, position[i], unit, dict(zip(g.joints, q[i])))
        for j, link in enumerate(g.links):
            p_ref, R_ref = reference[link]
            assert np.allclose(translations[i, j], p_ref, atol=1e-12), (link, translations[i, j], p_ref)
            assert np.allclose(rotations[i, j], R_ref, atol=1e-12), link


def test_normalized_quaternions():
    q = normalized_quaternions(np.array([[0, 0, 0, 0], [0, 0, 0, 2.0], [1, 1, 1, 1]]))
    assert np.allclose(q, [[0, 0, 0, 1], [0, 0, 0, 1], [0.5, 0.5, 0.5, 0.5]])


def test_a_mesh_s_vertex_and_face_colours_reach_the_view(tmp_path):
    """Colours a mesh file carries, not the URDF's: per vertex as written (PLY), and per face of a
    merged two-part mesh (each part its own vertices) as that part's colour on its vertices."""
    import trimesh

    from components.viewer.robot import mesh_arrays

    box = trimesh.creation.box((0.1, 0.2, 0.3))
    vertex_colours = np.array([[(37 * i) % 256, (91 * i) % 256, (53 * i) % 256, 255] for i in range(8)], np.uint8)
    box.visual = trimesh.visual.ColorVisuals(box, vertex_colors=vertex_colours)
    box.export(tmp_path / "vertex.ply")
    vertices, _, _, colours = mesh_arrays(tmp_path / "vertex.ply")
    order = [int(np.argmin(np.linalg.norm(box.vertices - v, axis=1))) for v in vertices]
    assert colours is not None and np.array_equal(colours, vertex_colours[order])

    red, blue = trimesh.creation.box((0.1, 0.1, 0.1)), trimesh.creation.box((0.1, 0.1, 0.1))
    blue.apply_translation((1.0, 0.0, 0.0))
    red.visual.face_colors, blue.visual.face_colors = (255, 0, 0, 255), (0, 0, 255, 255)
    trimesh.util.concatenate([red, blue]).export(tmp_path / "faces.ply")
    vertices, _, _, colours = mesh_arrays(tmp_path / "faces.ply")
    assert colours is not None
    on_blue = vertices[:, 0] > 0.5
    assert on_blue.sum() == 8 and (colours[on_blue] == (0, 0, 255, 255)).all()
    assert (colours[~on_blue] == (255, 0, 0, 255)).all()
