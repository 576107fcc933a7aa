"""The conversions between the world's coordinates and Pinocchio's, compiled (see
:mod:`components.dynamics.pinocchio_body`'s docstring): configuration, velocity and forces in
(``to_pinocchio``), accelerations out (``from_pinocchio``), and the mass matrix, a point's Jacobian
and its bias acceleration in the world's coordinates. numba, no fastmath: IEEE arithmetic, the
same bits at every run.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from components.dynamics import manifold_rk4


@numba.njit(cache=True)
def quaternion_entries(px, py, pz):
    """The quaternion [x, y, z, w] of the rotation vector (px, py, pz), w = cos(|phi|/2)."""
    t = math.sqrt(px * px + py * py + pz * pz)
    s = 0.5 - t * t / 48.0 if t < 1e-6 else math.sin(0.5 * t) / t  # sin(t/2) / t
    return s * px, s * py, s * pz, math.cos(0.5 * t)


@numba.njit(cache=True)
def to_pinocchio(x, v, Q, idx_q, nq, idx_v, rotation, q_pin, v_pin, tau_pin):
    """Pinocchio's configuration, velocity and generalized forces from the world's coordinates
    (written into q_pin, v_pin, tau_pin), and R_W_base into ``rotation``."""
    m = manifold_rk4.exp_entries(x[0], x[1], x[2])
    for i in range(3):
        rotation[i, 0], rotation[i, 1], rotation[i, 2] = m[3 * i], m[3 * i + 1], m[3 * i + 2]
    R = rotation
    q_pin[0], q_pin[1], q_pin[2] = x[3], x[4], x[5]
    q_pin[3], q_pin[4], q_pin[5], q_pin[6] = quaternion_entries(x[0], x[1], x[2])
    for i in range(3):
        vb, wb, fb, tb = 0.0, 0.0, 0.0, 0.0
        for j in range(3):
            vb += R[j, i] * v[3 + j]
            wb += R[j, i] * v[j]
            fb += R[j, i] * Q[3 + j]
            tb += R[j, i] * Q[j]
        v_pin[i], v_pin[3 + i], tau_pin[i], tau_pin[3 + i] = vb, wb, fb, tb
    for i in range(idx_q.shape[0]):
        k = 6 + i
        if nq[i] == 1:
            q_pin[idx_q[i]] = x[k]
        else:
            q_pin[idx_q[i]] = math.cos(x[k])
            q_pin[idx_q[i] + 1] = math.sin(x[k])
        v_pin[idx_v[i]] = v[k]
        tau_pin[idx_v[i]] = Q[k]


@numba.njit(cache=True)
def from_pinocchio(ddq, v_pin, rotation, idx_v, a):
    """The world's accelerations (into ``a``, which it returns) from Pinocchio's (the free
    flyer's spatial acceleration made classical)."""
    vb0, vb1, vb2, w0, w1, w2 = v_pin[0], v_pin[1], v_pin[2], v_pin[3], v_pin[4], v_pin[5]
    lin0, lin1, lin2 = ddq[0] + w1 * vb2 - w2 * vb1, ddq[1] + w2 * vb0 - w0 * vb2, ddq[2] + w0 * vb1 - w1 * vb0
    for i in range(3):
        a[i] = rotation[i, 0] * ddq[3] + rotation[i, 1] * ddq[4] + rotation[i, 2] * ddq[5]
        a[3 + i] = rotation[i, 0] * lin0 + rotation[i, 1] * lin1 + rotation[i, 2] * lin2
    for i in range(idx_v.shape[0]):
        a[6 + i] = ddq[idx_v[i]]
    return a


@numba.njit(cache=True)
def velocity_map(rotation, idx_v, nv):
    """T (nv, n): v_pin = T v, from the world's coordinates to Pinocchio's velocity (orthogonal)."""
    T = np.zeros((nv, 6 + idx_v.shape[0]))
    for i in range(3):
        for k in range(3):
            T[i, 3 + k] = rotation[k, i]  # v_b = R^T v
            T[3 + i, k] = rotation[k, i]  # omega_b = R^T omega
    for m in range(idx_v.shape[0]):
        T[idx_v[m], 6 + m] = 1.0
    return T


@numba.njit(cache=True)
def world_inverse_mass(upper, rotation, idx_v):
    """The world's M^-1 = T^T M_pin^-1 T from the upper triangle Pinocchio fills."""
    nv = upper.shape[0]
    M = np.empty((nv, nv))
    for i in range(nv):
        for j in range(i, nv):
            M[i, j] = M[j, i] = upper[i, j]
    T = velocity_map(rotation, idx_v, nv)
    return T.T @ M @ T


@numba.njit(cache=True)
def world_point_jacobian(J, r, rotation, idx_v):
    """(6, n) (angular; linear) over the world's coordinates, of a point at r (W) from a frame's
    origin, from the frame's Jacobian J (6, nv: linear; angular, world axes, Pinocchio's velocity)."""
    nv = J.shape[1]
    point = np.empty((6, nv))
    for c in range(nv):
        w0, w1, w2 = J[3, c], J[4, c], J[5, c]
        point[0, c], point[1, c], point[2, c] = w0, w1, w2
        point[3, c] = J[0, c] - (r[1] * w2 - r[2] * w1)  # v + omega x r
        point[4, c] = J[1, c] - (r[2] * w0 - r[0] * w2)
        point[5, c] = J[2, c] - (r[0] * w1 - r[1] * w0)
    return point @ velocity_map(rotation, idx_v, nv)


@numba.njit(cache=True)
def zero_world_acceleration(v_pin):
    """Pinocchio's acceleration where the world's is zero: (dv_b/dt, domega_b/dt) = (-omega_b x v_b, 0),
    joints 0 (v_b = R^T v: d(v_b)/dt = R^T dv/dt - omega_b x v_b)."""
    a = np.zeros(v_pin.shape[0])
    a[0] = -(v_pin[4] * v_pin[2] - v_pin[5] * v_pin[1])
    a[1] = -(v_pin[5] * v_pin[0] - v_pin[3] * v_pin[2])
    a[2] = -(v_pin[3] * v_pin[1] - v_pin[4] * v_pin[0])
    return a


@numba.njit(cache=True)
def point_acceleration(linear, alpha, w, r):
    """(alpha; a + alpha x r + w x (w x r)): the acceleration of a point at r from a frame's origin
    whose classical acceleration is a, angular acceleration alpha, angular velocity w (all W)."""
    out = np.empty(6)
    wr = np.array([w[1] * r[2] - w[2] * r[1], w[2] * r[0] - w[0] * r[2], w[0] * r[1] - w[1] * r[0]])
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        out[i] = alpha[i]
        out[3 + i] = linear[i] + (alpha[j] * r[k] - alpha[k] * r[j]) + (w[j] * wr[k] - w[k] * wr[j])
    return out
