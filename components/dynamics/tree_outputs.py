"""A Pinocchio body's outputs over its tree, compiled: base pose and twist, CoM, its velocity and
the momentum (``body_summary``; it agrees with Pinocchio's centroidal momentum to rounding).
numba, no fastmath: IEEE arithmetic, the same bits at every run.
"""

from __future__ import annotations

import numba
import numpy as np

from components.dynamics import tree_forces
from components.dynamics.pinocchio_conversions import quaternion_entries


@numba.njit(cache=True)
def body_summary(x, v, joints, frames, links, link_joint, out):
    """The body's outputs at (x, v) into ``out`` (25): base position, quaternion (w >= 0), twist
    (v, omega), then ``tree_centroidal``'s CoM, its velocity, momentum."""
    out[0], out[1], out[2] = x[3], x[4], x[5]
    qx, qy, qz, qw = quaternion_entries(x[0], x[1], x[2])
    if qw < 0.0:
        qx, qy, qz, qw = -qx, -qy, -qz, -qw
    out[3], out[4], out[5], out[6] = qx, qy, qz, qw
    out[7], out[8], out[9], out[10], out[11], out[12] = v[3], v[4], v[5], v[0], v[1], v[2]
    tree_centroidal(x, v, joints, frames, links, link_joint, out[13:25])


@numba.njit(cache=True)
def tree_centroidal(x, v, joints, frames, links, link_joint, out):
    """The body's CoM, its velocity and the momentum (linear, angular about the CoM), W, at (x, v)
    into ``out`` (12): forward kinematics over the tree (``tree_forces.tree_kinematics``), then per
    link with mass m, CoM c, inertia I (about c, W axes) and angular velocity w: p = sum m v_c,
    L = sum (I w + m (c - com) x v_c)."""
    nj, nl = joints.shape[0], link_joint.shape[0]
    block = np.zeros(21 * nj + 12 * nl + 24)
    per_joint = block[: 12 * nj].reshape((4, nj, 3))
    rotation = block[12 * nj : 21 * nj].reshape((nj, 3, 3))
    link_values = block[21 * nj : 21 * nj + 12 * nl].reshape((nl, 4, 3))  # per link: c, v_c, I w, R^T w
    tree_forces.tree_kinematics(
        x,
        v,
        joints,
        frames,
        True,
        rotation,
        per_joint[0],
        per_joint[1],
        per_joint[2],
        per_joint[3],
        block[21 * nj + 12 * nl : 21 * nj + 12 * nl + 24],
    )
    out[:] = 0.0
    mass = 0.0
    for n in range(nl):
        j = link_joint[n]
        Rj, link, c, v_c, Iw = rotation[j], links[n], link_values[n, 0], link_values[n, 1], link_values[n, 2]
        w = per_joint[2, j]
        m = link[12]
        mass += m
        for i in range(3):
            c[i] = Rj[i, 0] * link[0] + Rj[i, 1] * link[1] + Rj[i, 2] * link[2]  # CoM from the joint's origin
        v_c[0] = per_joint[3, j, 0] + w[1] * c[2] - w[2] * c[1]
        v_c[1] = per_joint[3, j, 1] + w[2] * c[0] - w[0] * c[2]
        v_c[2] = per_joint[3, j, 2] + w[0] * c[1] - w[1] * c[0]
        for i in range(3):
            c[i] += per_joint[0, j, i]
            out[i] += m * c[i]
            out[6 + i] += m * v_c[i]
        local = link_values[n, 3]  # I w = Rj I_local Rj^T w
        for i in range(3):
            local[i] = Rj[0, i] * w[0] + Rj[1, i] * w[1] + Rj[2, i] * w[2]
        t0 = link[3] * local[0] + link[4] * local[1] + link[5] * local[2]
        t1 = link[6] * local[0] + link[7] * local[1] + link[8] * local[2]
        t2 = link[9] * local[0] + link[10] * local[1] + link[11] * local[2]
        for i in range(3):
            Iw[i] = Rj[i, 0] * t0 + Rj[i, 1] * t1 + Rj[i, 2] * t2
    for i in range(3):
        out[i] /= mass
        out[3 + i] = out[6 + i] / mass
    for n in range(nl):
        c, v_c, Iw = link_values[n, 0], link_values[n, 1], link_values[n, 2]
        m = links[n, 12]
        d0, d1, d2 = c[0] - out[0], c[1] - out[1], c[2] - out[2]
        out[9] += Iw[0] + m * (d1 * v_c[2] - d2 * v_c[1])
        out[10] += Iw[1] + m * (d2 * v_c[0] - d0 * v_c[2])
        out[11] += Iw[2] + m * (d0 * v_c[1] - d1 * v_c[0])
