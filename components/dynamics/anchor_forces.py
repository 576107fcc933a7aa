"""The orbital environment on a DART body's links as generalized forces, through its anchors' Jacobians.

A link welded to its parent moves with the nearest ancestor that is not welded: its anchor. The
links' environment (:mod:`components.dynamics.link_forces`, per link) is summed in their anchor's
axes and mapped through the anchors' body Jacobians (Q = sum_a J_a^T W_a), which also give the
anchors' poses: ``generalized_forces``, one compiled call per rk4 stage, forces in the world's
coordinates (the base's rotation, then its origin, then the joints).

Inputs of ``generalized_forces`` (all float64 or int64 arrays, SI units):

| argument | shape | meaning |
|---|---|---|
| J | (6, c) | the anchors' body Jacobians side by side, [angular; linear], anchor axes |
| rotation_columns | (k, 3) | columns of J that hold the base rotation dofs of each anchor |
| jacobian_anchor, jacobian_dofs | (c,) | anchor and dof of each column of J |
| anchor_slot | (n,) | anchor of each massive link |
| com, inertia, mass | (n, 3), (n, 3, 3), (n,) | link CoM and inertia about it in anchor axes, kg |
| R, V | (3,) | reference point from the Earth's centre (m) and its velocity (m/s), W axes |
| base | (3,) | base origin in W, m |
| mu | - | gravitational parameter, m^3/s^2 |
| tidal, gravity_gradient, drag | - | which terms to include |
| drag_k | (n,) | 1/2 Cd A per link, m^2 |
| v_com | (n, 3) | CoM velocity in W, m/s (read only with drag) |
| h0, rho0, scale_height | (b,) | the atmosphere's bands: base altitude m, density kg/m^3, scale height m |
| earth_rate, earth_radius | - | rad/s about W z, m |
| tau | (ndofs,) | joint generalized forces (added to the result) |
| force, torque | (n, 3) | filled with each link's environment force at its CoM and torque about it, anchor axes |
| srp, light | -, (13,) | solar radiation pressure on or off; the Sun (``link_forces.LIGHT_SIZE``) |
| srp_links | (n, 3) | per link: Cr A (m^2, 0: no cannonball), first row and count of its facets |
| facets | (m, 9) | facets (components.space.srp), anchor axes, centres from the link's CoM (m) |
| third | (2,) | GM of the Sun, of the Moon (m^3/s^2) whose tidal force acts; 0: that body off (their positions: ``light``) |

Frames: the base rotation columns of anchor a's Jacobian are R_a^T (angular rows) and
-[o_a]x R_a^T (linear rows), with o_a = R_a^T (p_a - p) the anchor origin relative to the base
origin p in anchor axes: one Jacobian gives the anchor's pose too.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from components.dynamics.link_forces import drag_factor, link_environment, link_srp, link_third_bodies


# long: one compiled call per rk4 stage; its 30 arguments (the table above) take a line each and the loop's terms share one link's scratch
@numba.njit(cache=True)
def generalized_forces(
    J,
    rotation_columns,
    jacobian_anchor,
    jacobian_dofs,
    anchor_slot,
    com,
    inertia,
    mass,
    R,
    V,
    base,
    mu,
    tidal,
    gravity_gradient,
    drag,
    drag_k,
    v_com,
    h0,
    rho0,
    scale_height,
    earth_rate,
    earth_radius,
    tau,
    force,
    torque,
    srp,
    light,
    srp_links,
    facets,
    third,
):
    rotation_T, R_local, base_local = anchor_frames(J, rotation_columns, R, base)
    r2 = R[0] * R[0] + R[1] * R[1] + R[2] * R[2]
    r = math.sqrt(r2)
    wrench = np.zeros((rotation_T.shape[0], 6))  # per anchor, about its origin: [torque; force]
    d = np.empty(3)
    f = np.empty(3)
    t = np.empty(3)
    x = np.empty(3)
    v_rel = np.empty(3)
    lever = np.empty(3)
    third_on = third[0] > 0.0 or third[1] > 0.0
    for n in range(anchor_slot.shape[0]):
        a = anchor_slot[n]
        for i in range(3):
            d[i] = base_local[a, i] + com[n, i]  # link CoM from the reference point
        link_environment(R_local[a], d, mass[n], inertia[n], r2, r, mu, tidal, gravity_gradient, f, t)
        if third_on:
            link_third_bodies(R, d, mass[n], inertia[n], third, light, rotation_T[a], x, v_rel, lever, f)
        if drag and drag_k[n] > 0.0:
            _from_earth(R, rotation_T[a], d, x)
            c = drag_factor(x, V, v_com[n], drag_k[n], h0, rho0, scale_height, earth_rate, earth_radius, v_rel)
            for i in range(3):
                value = 0.0
                for j in range(3):
                    value += rotation_T[a, i, j] * v_rel[j]
                f[i] += c * value
        if srp and (srp_links[n, 0] > 0.0 or srp_links[n, 2] > 0.0):
            _from_earth(R, rotation_T[a], d, x)
            start = int(srp_links[n, 1])
            facet_rows = facets[start : start + int(srp_links[n, 2])]
            link_srp(x, rotation_T[a], light, srp_links[n, 0], facet_rows, v_rel, lever, f, t)
        force[n, 0], force[n, 1], force[n, 2] = f[0], f[1], f[2]
        torque[n, 0], torque[n, 1], torque[n, 2] = t[0], t[1], t[2]
        c0, c1, c2 = com[n, 0], com[n, 1], com[n, 2]
        wrench[a, 0] += t[0] + c1 * f[2] - c2 * f[1]
        wrench[a, 1] += t[1] + c2 * f[0] - c0 * f[2]
        wrench[a, 2] += t[2] + c0 * f[1] - c1 * f[0]
        wrench[a, 3] += f[0]
        wrench[a, 4] += f[1]
        wrench[a, 5] += f[2]
    return anchor_joint_forces(J, jacobian_anchor, jacobian_dofs, wrench, tau)


@numba.njit(cache=True)
def anchor_frames(J, rotation_columns, R, base):
    """Each anchor's R_a^T (k, 3, 3), the reference point R (k, 3) and the anchor's origin from the
    base origin plus the base (k, 3), in the anchor's axes, from the base rotation columns of its
    Jacobian (the module's Frames)."""
    k = rotation_columns.shape[0]
    rotation_T = np.empty((k, 3, 3))
    R_local = np.empty((k, 3))
    base_local = np.empty((k, 3))
    for a in range(k):
        for i in range(3):
            for j in range(3):
                rotation_T[a, i, j] = J[i, rotation_columns[a, j]]
        # -[o]x = S R_a with S the linear rows: o = ((S R_a)[1, 2], (S R_a)[2, 0], (S R_a)[0, 1])
        for i, (row, col) in enumerate(((1, 2), (2, 0), (0, 1))):
            value = 0.0
            for j in range(3):
                value += J[3 + row, rotation_columns[a, j]] * rotation_T[a, col, j]
            base_local[a, i] = value  # o_a for now
        for i in range(3):
            r_i, b_i = 0.0, 0.0
            for j in range(3):
                r_i += rotation_T[a, i, j] * R[j]
                b_i += rotation_T[a, i, j] * base[j]
            R_local[a, i] = r_i
            base_local[a, i] += b_i  # R_a^T p + o_a: the anchor origin in W, anchor axes
    return rotation_T, R_local, base_local


@numba.njit(cache=True)
def _from_earth(R, rotation_T, d, x):
    """x = R + rotation_T^T d: a point d from the reference point in anchor axes, from the Earth's centre in W."""
    for i in range(3):
        x[i] = R[i]
        for j in range(3):
            x[i] += rotation_T[j, i] * d[j]


@numba.njit(cache=True)
def anchor_joint_forces(J, jacobian_anchor, jacobian_dofs, wrench, tau):
    """tau plus the anchors' wrenches (k, 6: [torque; force] about each anchor's origin, its axes)
    through their Jacobians' columns: Q = tau + sum_a J_a^T W_a."""
    out = tau.copy()
    for c in range(jacobian_dofs.shape[0]):
        a = jacobian_anchor[c]
        value = 0.0
        for i in range(6):
            value += J[i, c] * wrench[a, i]
        out[jacobian_dofs[c]] += value
    return out
