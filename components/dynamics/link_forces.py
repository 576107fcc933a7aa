"""The orbital environment on a body's links, as the generalized forces DART takes: one compiled loop.

The formulas are those of :mod:`components.dynamics.environment` (tidal force, gravity-gradient
torque, drag), evaluated per link in its anchor's axes and mapped to generalized forces through the
anchors' Jacobians (Q = sum_a J_a^T W_a). This runs at each of the four rk4 stages of every step;
written with numpy it cost ~60 us a stage in ~40 calls on arrays of a few rows, so the loop over
the links is compiled with numba (nopython, no fastmath: IEEE arithmetic, the same bits on every
run on a machine). ``tests/unit/test_dynamics_world.py`` and ``test_dynamics_pinocchio.py`` check
it against DART's and Pinocchio's own handling of the same per-link wrenches.

Inputs of ``generalized_forces`` (all float64 or int64 arrays, SI units):

| argument | shape | meaning |
|---|---|---|
| J | (6, c) | the anchors' body Jacobians side by side, [angular; linear], anchor axes |
| rotation_columns | (k, 3) | columns of J that hold the base rotation dofs of each anchor |
| jacobian_anchor, jacobian_dofs | (c,) | anchor and DART dof of each column of J |
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
| tau | (ndofs,) | joint generalized forces, DART order (added to the result) |
| force, torque | (n, 3) | filled with each link's environment force at its CoM and torque about it, anchor axes |

Frames: the base rotation columns of anchor a's Jacobian are R_a^T (angular rows) and
-[o_a]x R_a^T (linear rows), with o_a = R_a^T (p_a - p) the anchor origin relative to the base
origin p in anchor axes: one Jacobian gives the anchor's pose too.
"""
from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True)
def generalized_forces(J, rotation_columns, jacobian_anchor, jacobian_dofs, anchor_slot, com, inertia, mass,
                       R, V, base, mu, tidal, gravity_gradient, drag, drag_k, v_com, h0, rho0, scale_height,
                       earth_rate, earth_radius, tau, force, torque):
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
            base_local[a, i] = value              # o_a for now
        for i in range(3):
            r_i, b_i = 0.0, 0.0
            for j in range(3):
                r_i += rotation_T[a, i, j] * R[j]
                b_i += rotation_T[a, i, j] * base[j]
            R_local[a, i] = r_i
            base_local[a, i] += b_i               # R_a^T p + o_a: the anchor origin in W, anchor axes
    r2 = R[0] * R[0] + R[1] * R[1] + R[2] * R[2]
    r = math.sqrt(r2)
    wrench = np.zeros((k, 6))                     # per anchor, about its origin: [torque; force]
    d = np.empty(3)
    rho = np.empty(3)
    f = np.empty(3)
    for n in range(anchor_slot.shape[0]):
        a = anchor_slot[n]
        w = 0.0
        for i in range(3):
            d[i] = base_local[a, i] + com[n, i]   # link CoM from the reference point
            rho[i] = R_local[a, i] + d[i]         # and from the Earth's centre
            w += d[i] * (rho[i] + R_local[a, i])  # 2 R.d + d.d = s^2 - r^2 (no cancellation)
        s2 = w + r2
        s = math.sqrt(s2)
        s3 = s2 * s
        for i in range(3):
            f[i] = 0.0
        if tidal:
            # m (g(R + d) - g(R)) = -mu m [d / s^3 + R (r - s)(r^2 + r s + s^2) / (r^3 s^3)]
            scale = mass[n] / s3 * -mu
            factor = scale * w * (s + r2 / (s + r)) / (r2 * r)
            for i in range(3):
                f[i] = scale * d[i] - factor * R_local[a, i]
        if drag and drag_k[n] > 0.0:
            # -1/2 rho(h) Cd A |v_rel| v_rel, v_rel against an atmosphere turning with the Earth
            x = np.empty(3)
            for i in range(3):
                x[i] = R[i]
                for j in range(3):
                    x[i] += rotation_T[a, j, i] * d[j]
            v_rel = np.empty(3)
            v_rel[0] = V[0] + v_com[n, 0] + earth_rate * x[1]
            v_rel[1] = V[1] + v_com[n, 1] - earth_rate * x[0]
            v_rel[2] = V[2] + v_com[n, 2]
            altitude = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) - earth_radius
            band = 0
            while band + 1 < h0.shape[0] and h0[band + 1] <= altitude:
                band += 1
            density = rho0[band] * math.exp(-(altitude - h0[band]) / scale_height[band])
            speed = math.sqrt(v_rel[0] * v_rel[0] + v_rel[1] * v_rel[1] + v_rel[2] * v_rel[2])
            c = -density * drag_k[n] * speed
            for i in range(3):
                value = 0.0
                for j in range(3):
                    value += rotation_T[a, i, j] * v_rel[j]
                f[i] += c * value
        t0, t1, t2 = 0.0, 0.0, 0.0
        if gravity_gradient:
            # 3 mu / |rho|^5 (rho x I rho)
            i0 = inertia[n, 0, 0] * rho[0] + inertia[n, 0, 1] * rho[1] + inertia[n, 0, 2] * rho[2]
            i1 = inertia[n, 1, 0] * rho[0] + inertia[n, 1, 1] * rho[1] + inertia[n, 1, 2] * rho[2]
            i2 = inertia[n, 2, 0] * rho[0] + inertia[n, 2, 1] * rho[1] + inertia[n, 2, 2] * rho[2]
            g = 3.0 * mu / (s2 * s3)
            t0 = g * (rho[1] * i2 - rho[2] * i1)
            t1 = g * (rho[2] * i0 - rho[0] * i2)
            t2 = g * (rho[0] * i1 - rho[1] * i0)
        force[n, 0], force[n, 1], force[n, 2] = f[0], f[1], f[2]
        torque[n, 0], torque[n, 1], torque[n, 2] = t0, t1, t2
        c0, c1, c2 = com[n, 0], com[n, 1], com[n, 2]
        wrench[a, 0] += t0 + c1 * f[2] - c2 * f[1]
        wrench[a, 1] += t1 + c2 * f[0] - c0 * f[2]
        wrench[a, 2] += t2 + c0 * f[1] - c1 * f[0]
        wrench[a, 3] += f[0]
        wrench[a, 4] += f[1]
        wrench[a, 5] += f[2]
    out = tau.copy()
    for c in range(jacobian_dofs.shape[0]):
        a = jacobian_anchor[c]
        value = 0.0
        for i in range(6):
            value += J[i, c] * wrench[a, i]
        out[jacobian_dofs[c]] += value
    return out
