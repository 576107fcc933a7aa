"""A URDF as Pinocchio's free-flyer model, and the tables of its tree and links the compiled kernels read
(:mod:`components.dynamics.tree_forces`, :mod:`components.dynamics.tree_outputs`)."""

from __future__ import annotations

import math

import numpy as np

from components.dynamics import tree_forces
from components.dynamics.bodies import BodySpec, ModelError
from components.robots.urdf import UrdfModel


def load_model(pin, spec: BodySpec, model: UrdfModel, locked: dict[str, float]):
    """Pinocchio's model of the URDF on a free flyer, the ``locked`` joints welded at their
    positions, without gravity; ModelError if Pinocchio cannot load it."""
    try:
        full = pin.buildModelFromXML(model.text, pin.JointModelFreeFlyer())
    except (RuntimeError, ValueError) as e:
        raise ModelError(f"{spec.name}.urdf", f"Pinocchio could not load {spec.urdf}: {e}") from None
    if locked:
        reference = pin.neutral(full)
        for name, value in locked.items():
            joint = full.joints[full.getJointId(name)]
            if joint.nq == 2:  # continuous: (cos, sin)
                reference[joint.idx_q : joint.idx_q + 2] = math.cos(value), math.sin(value)
            else:
                reference[joint.idx_q] = value
        pm = pin.buildReducedModel(full, [full.getJointId(n) for n in locked], reference)
    else:
        pm = full
    pm.gravity = pin.Motion.Zero()
    return pm


def tree_tables(pm, model: UrdfModel, free_joints: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """The tree for the environment (``tree_forces.tree_kinematics``; joint 1 is the free flyer):
    per joint its parent, kind and coordinate, and its placement and axis."""
    nj = pm.njoints
    tree_joints = np.zeros((nj, 3), dtype=np.int64)  # parent, kind, coordinate
    tree_frames = np.zeros((nj, 15))  # placement R, p; axis
    for j in range(1, nj):
        placement = pm.jointPlacements[j]
        tree_frames[j, :12] = np.concatenate([placement.rotation.ravel(), placement.translation])
        tree_joints[j, 0] = pm.parents[j]
        if j >= 2:
            joint = model.joint(pm.names[j])
            kind = tree_forces.PRISMATIC if joint.type == "prismatic" else tree_forces.REVOLUTE
            tree_joints[j, 1:] = kind, 6 + free_joints.index(joint.name)
            tree_frames[j, 12:] = joint.axis
    return tree_joints, tree_frames


def link_rows(pm, model: UrdfModel, massive_links: np.ndarray, frame_id: dict[str, int], drag_k):
    """Per link with mass: its joint, its row (CoM, inertia about it in its joint's frame, mass,
    1/2 Cd A) and its frame's placement in its joint's frame."""
    joint_of, rows, placements = [], [], []
    for i in massive_links:
        link = model.links[i]
        frame = pm.frames[frame_id[link.name]]
        P = frame.placement
        joint_of.append(frame.parentJoint)
        placements.append(P)
        inertia = P.rotation @ np.array(link.inertia).reshape(3, 3) @ P.rotation.T
        rows.append(
            np.concatenate(
                [
                    P.rotation @ np.array(link.com) + P.translation,
                    inertia.ravel(),
                    [link.mass, drag_k[link.name]],
                ]
            )
        )
    return joint_of, rows, placements
