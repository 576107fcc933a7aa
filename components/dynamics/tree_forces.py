"""The orbital environment on a Pinocchio body's links as generalized forces, over the model's tree.

The joint frames by forward kinematics over the tree (``tree_kinematics``, joint 1 the free base),
each link's environment (:mod:`components.dynamics.link_forces`) in W axes, and the joint forces
by a backward pass over the tree (``tree_joint_forces``: Q_j = s_j . the wrench of everything
beyond joint j): ``tree_generalized_forces``, one compiled call per rk4 stage, forces in the
world's coordinates (the base's rotation, then its origin, then the joints). numba, no fastmath:
IEEE arithmetic, the same bits at every run.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from components.dynamics.link_forces import (
    cross,
    drag_factor,
    link_environment,
    link_srp,
    link_third_bodies,
    rotate,
)
from components.dynamics.manifold_rk4 import exp_entries

REVOLUTE, PRISMATIC = 1, 2  # tree joint kinds (0: the free base)


@numba.njit(cache=True)
def _axis_rotation(u, angle, out):
    """out = exp([u]x angle) for a unit axis u: cos I + sin [u]x + (1 - cos) u u^T (1 - cos as
    2 sin^2(angle / 2): no cancellation at small angles)."""
    c, s = math.cos(angle), math.sin(angle)
    h = math.sin(0.5 * angle)
    k = 2.0 * h * h
    for i in range(3):
        for j in range(3):
            out[i, j] = k * u[i] * u[j]
        out[i, i] += c
    out[0, 1] -= s * u[2]
    out[1, 0] += s * u[2]
    out[0, 2] += s * u[1]
    out[2, 0] -= s * u[1]
    out[1, 2] -= s * u[0]
    out[2, 1] += s * u[0]


@numba.njit(cache=True)
def tree_kinematics(x, v, joints, frames, with_velocity, rotation, position, joint_axis, angular, linear, work):
    """Joint frames in W over a tree whose joint 1 is the free base, from the world's coordinates
    x, v (base rotation vector, base origin, joints): ``rotation``, ``position`` (nj, 3, 3),
    (nj, 3); ``joint_axis`` (nj, 3), W; with ``with_velocity`` also each joint frame's
    ``angular`` velocity and its origin's ``linear`` one (W). ``joints`` (nj, 3): parent, kind
    (REVOLUTE, PRISMATIC; 0 for the base), coordinate; ``frames`` (nj, 15): the joint's placement
    in its parent's frame (rotation row-major, translation), its axis in its own frame. Parents
    come first. ``work``: 24 floats of scratch."""
    m = exp_entries(x[0], x[1], x[2])
    for r in range(3):
        rotation[1, r, 0], rotation[1, r, 1], rotation[1, r, 2] = m[3 * r], m[3 * r + 1], m[3 * r + 2]
    position[1] = x[3:6]
    if with_velocity:
        angular[1] = v[0:3]
        linear[1] = v[3:6]
    matrices = work[:18].reshape((2, 3, 3))
    Rj, E = matrices[0], matrices[1]
    vectors = work[18:24].reshape((2, 3))
    lever, w_x_lever = vectors[0], vectors[1]
    for j in range(2, joints.shape[0]):
        p, kind, k = joints[j, 0], joints[j, 1], joints[j, 2]
        f = frames[j]
        Rp = rotation[p]
        for r in range(3):  # Rj = R_p placement_R, origin = R_p placement_p + p_p
            for c in range(3):
                Rj[r, c] = Rp[r, 0] * f[c] + Rp[r, 1] * f[3 + c] + Rp[r, 2] * f[6 + c]
            position[j, r] = Rp[r, 0] * f[9] + Rp[r, 1] * f[10] + Rp[r, 2] * f[11] + position[p, r]
        u = joint_axis[j]
        rotate(Rj, f[12:15], u)
        value = x[k]
        if kind == REVOLUTE:
            _axis_rotation(f[12:15], value, E)
            for r in range(3):
                for c in range(3):
                    rotation[j, r, c] = Rj[r, 0] * E[0, c] + Rj[r, 1] * E[1, c] + Rj[r, 2] * E[2, c]
        else:
            rotation[j] = Rj
            for r in range(3):
                position[j, r] += u[r] * value
        if with_velocity:
            rate = v[k]
            for r in range(3):
                lever[r] = position[j, r] - position[p, r]
            cross(angular[p], lever, w_x_lever)
            for r in range(3):
                angular[j, r] = angular[p, r] + (u[r] * rate if kind == REVOLUTE else 0.0)
                linear[j, r] = linear[p, r] + w_x_lever[r] + (u[r] * rate if kind == PRISMATIC else 0.0)


# long: one compiled call per rk4 stage; its 22 arguments take a line each and the loop's terms share one link's scratch
@numba.njit(cache=True)
def tree_generalized_forces(
    x,
    v,
    tau,
    joints,
    frames,
    links,
    link_joint,
    R,
    V,
    mu,
    tidal,
    gravity_gradient,
    drag,
    atmosphere,
    earth_rate,
    earth_radius,
    force,
    torque,
    srp,
    light,
    facets,
    third,
):
    """``tau`` plus the environment's generalized forces (world coordinates) of a body given as a
    tree (``joints``, ``frames``: see ``tree_kinematics``). Links: ``links`` (n, 17) their CoM (3)
    and inertia about it (9, row-major) in their joint's frame, mass, 1/2 Cd A, then for SRP (with
    ``srp``: ``link_srp``, ``light``) Cr A and their first row and count in ``facets`` (joint's
    axes, centres from the CoM); ``link_joint``
    (n,) their joint. ``atmosphere`` (3, b): the bands' base altitude, density, scale height.
    Fills ``force``, ``torque`` (n, 3): each link's environment force at its CoM and torque about
    it, W axes."""
    nj = joints.shape[0]
    block = np.zeros(27 * nj + 63)  # one allocation (a call's few microseconds count)
    per_joint = block[: 18 * nj].reshape((6, nj, 3))
    rotation = block[18 * nj : 27 * nj].reshape((nj, 3, 3))
    position, joint_axis, angular, linear = per_joint[0], per_joint[1], per_joint[2], per_joint[3]
    total_force, total_torque = per_joint[4], per_joint[5]  # per joint: its links' wrench about the W origin
    tree_kinematics(x, v, joints, frames, drag, rotation, position, joint_axis, angular, linear, block[27 * nj + 39 :])
    r2 = R[0] * R[0] + R[1] * R[1] + R[2] * R[2]
    r = math.sqrt(r2)
    scratch = block[27 * nj : 27 * nj + 39].reshape((13, 3))
    f, t, d, c_W, v_rel, x_earth, v_com, lever = (
        scratch[0],
        scratch[1],
        scratch[2],
        scratch[3],
        scratch[4],
        scratch[5],
        scratch[6],
        scratch[7],
    )
    about, R_local, d_local, f_local, t_local = scratch[8], scratch[9], scratch[10], scratch[11], scratch[12]
    third_on = third[0] > 0.0 or third[1] > 0.0
    for n in range(link_joint.shape[0]):
        j = link_joint[n]
        Rj = rotation[j]
        link = links[n]
        rotate(Rj, link[0:3], c_W)
        for i in range(3):
            d[i] = c_W[i] + position[j, i]  # CoM from the reference point, W
        for i in range(3):  # R and d in the joint's frame, where the inertia is given
            R_local[i] = Rj[0, i] * R[0] + Rj[1, i] * R[1] + Rj[2, i] * R[2]
            d_local[i] = Rj[0, i] * d[0] + Rj[1, i] * d[1] + Rj[2, i] * d[2]
        inertia = link[3:12].reshape((3, 3))
        link_environment(R_local, d_local, link[12], inertia, r2, r, mu, tidal, gravity_gradient, f_local, t_local)
        if third_on:
            link_third_bodies(R, d_local, link[12], inertia, third, light, Rj.T, x_earth, v_rel, lever, f_local)
        if srp and (link[14] > 0.0 or link[16] > 0.0):
            for i in range(3):
                x_earth[i] = R[i] + d[i]
            start = int(link[15])
            link_srp(
                x_earth, Rj.T, light, link[14], facets[start : start + int(link[16])], v_rel, lever, f_local, t_local
            )
        rotate(Rj, f_local, f)
        rotate(Rj, t_local, t)
        if drag and link[13] > 0.0:
            cross(angular[j], c_W, lever)
            for i in range(3):
                v_com[i] = linear[j, i] + lever[i]
                x_earth[i] = R[i] + d[i]
            c = drag_factor(
                x_earth,
                V,
                v_com,
                link[13],
                atmosphere[0],
                atmosphere[1],
                atmosphere[2],
                earth_rate,
                earth_radius,
                v_rel,
            )
            for i in range(3):
                f[i] += c * v_rel[i]
        for i in range(3):
            force[n, i] = f[i]
            torque[n, i] = t[i]
            total_force[j, i] += f[i]
        total_torque[j, 0] += t[0] + d[1] * f[2] - d[2] * f[1]
        total_torque[j, 1] += t[1] + d[2] * f[0] - d[0] * f[2]
        total_torque[j, 2] += t[2] + d[0] * f[1] - d[1] * f[0]
    return tree_joint_forces(joints, position, joint_axis, total_force, total_torque, tau, about)


@numba.njit(cache=True)
def tree_joint_forces(joints, position, joint_axis, total_force, total_torque, tau, about):
    """tau plus the joints' generalized forces of the links' wrenches per joint (``total_force``,
    ``total_torque``: about the W origin, W axes; summed here into each joint's ancestors, children
    before parents): Q_j = s_j . the wrench of everything beyond joint j, about its origin; the
    base's torque and force. ``about``: scratch (3,)."""
    nj = joints.shape[0]
    for j in range(nj - 1, 1, -1):  # children before parents
        for i in range(3):
            total_force[joints[j, 0], i] += total_force[j, i]
            total_torque[joints[j, 0], i] += total_torque[j, i]
    out = tau.copy()
    for j in range(1, nj):
        F, T = total_force[j], total_torque[j]
        cross(position[j], F, about)
        for i in range(3):
            about[i] = T[i] - about[i]  # about the joint's origin
        if j == 1:
            for i in range(3):
                out[i] += about[i]
                out[3 + i] += F[i]
        elif joints[j, 1] == REVOLUTE:
            u = joint_axis[j]
            out[joints[j, 2]] += u[0] * about[0] + u[1] * about[1] + u[2] * about[2]
        else:
            u = joint_axis[j]
            out[joints[j, 2]] += u[0] * F[0] + u[1] * F[1] + u[2] * F[2]
    return out
