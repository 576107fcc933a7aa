"""The arithmetic between the stages of the manifold RK4 of :mod:`components.dynamics.world`, compiled.

A stage state is q0 (+) xi with velocities v (DART order: the FreeJoint's rotation first). For
the FreeJoint the rotation moves as R = exp(xi_w) R0 at world angular velocity omega, so
d(xi_w)/dt = J_l(xi_w)^-1 omega; every other coordinate has d(xi)/dt = v. The few vector
operations per stage cost more in numpy calls (~1 us each) than in arithmetic, so they run as
compiled functions (numba, no fastmath: IEEE arithmetic, the same bits at every run).

``moved`` forms q0 (+) xi itself rather than through DART's ``integratePositions``, whose SO(3)
exponential is truncated for angles below 1e-3 rad (an error of ~t^3/6 per stage: at 0.25 ms steps
a tumbling body's attitude drifted to 4e-7 where it should reach 1e-13). ``exp_so3`` and
``log_so3`` are the compiled twins of :mod:`components.rotations`' (which the processes without
numba use), exact to rounding at every angle.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True)
def so3_left_jacobian_inverse_times(phi: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """J_l(phi)^-1 omega (3,) (``rate_entries``)."""
    return np.array(rate_entries(phi, omega))


@numba.njit(cache=True)
def rate_entries(phi: np.ndarray, omega: np.ndarray):
    """J_l(phi)^-1 omega, three floats (no array: a compiled caller allocates nothing): the rate
    of phi for R = exp(phi) R0 turning at world angular velocity omega. J_l^-1 = I - [phi]x / 2 + (1 - (t/2) cot(t/2)) / t^2 [phi]x^2, t = |phi| (the
    coefficient by its series below t^2 = 1e-6, where the closed form loses digits)."""
    px, py, pz = phi[0], phi[1], phi[2]
    wx, wy, wz = omega[0], omega[1], omega[2]
    t2 = px * px + py * py + pz * pz
    if t2 < 1e-6:
        c = 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0
    else:
        t = math.sqrt(t2)
        c = (1.0 - 0.5 * t / math.tan(0.5 * t)) / t2
    cx, cy, cz = py * wz - pz * wy, pz * wx - px * wz, px * wy - py * wx  # phi x omega
    dx, dy, dz = py * cz - pz * cy, pz * cx - px * cz, px * cy - py * cx  # phi x (phi x omega)
    return wx - 0.5 * cx + c * dx, wy - 0.5 * cy + c * dy, wz - 0.5 * cz + c * dz


@numba.njit(cache=True)
def stage(c: float, v0: np.ndarray, rate: np.ndarray, acceleration: np.ndarray):
    """The next stage from the last one's derivatives: xi = c rate, v = v0 + c acceleration, and
    the rate of xi there, (xi, v, d(xi)/dt)."""
    xi = c * rate
    v = v0 + c * acceleration
    next_rate = v.copy()
    next_rate[:3] = so3_left_jacobian_inverse_times(xi[:3], v[:3])
    return xi, v, next_rate


@numba.njit(cache=True)
def combine(h: float, v0: np.ndarray, d1, d2, d3, d4, a1, a2, a3, a4):
    """The step: xi = h/6 (d1 + 2 d2 + 2 d3 + d4), v = v0 + h/6 (a1 + 2 a2 + 2 a3 + a4)."""
    w = h / 6.0
    return w * (d1 + 2.0 * d2 + 2.0 * d3 + d4), v0 + w * (a1 + 2.0 * a2 + 2.0 * a3 + a4)


@numba.njit(cache=True)
def exp_so3(phi: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector phi (rad) (``exp_entries``)."""
    m = exp_entries(phi[0], phi[1], phi[2])
    return np.array([[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]])


@numba.njit(cache=True)
def exp_entries(x: float, y: float, z: float):
    """The rotation matrix of the rotation vector (x, y, z) (rad), nine floats row by row:
    I + sin t/t K + 2 sin^2(t/2)/t^2 K^2, K = [phi]x, t = |phi|; the half-angle form has no
    cancellation as t -> 0 (series below 1e-8)."""
    t = math.sqrt(x * x + y * y + z * z)
    if t < 1e-8:
        a, b = 1.0, 0.5
    else:
        a = math.sin(t) / t
        s = math.sin(0.5 * t) / t
        b = 2.0 * s * s
    return (
        1.0 - b * (y * y + z * z),
        b * x * y - a * z,
        b * x * z + a * y,
        b * x * y + a * z,
        1.0 - b * (x * x + z * z),
        b * y * z - a * x,
        b * x * z - a * y,
        b * y * z + a * x,
        1.0 - b * (x * x + y * y),
    )


@numba.njit(cache=True)
def log_so3(m: np.ndarray) -> np.ndarray:
    """Rotation vector (rad, angle in [0, pi]) of the rotation matrix m; see rotations.log_so3."""
    return np.array(log_entries(m))


@numba.njit(cache=True)
def log_entries(m: np.ndarray):
    """``log_so3`` as three floats."""
    v0, v1, v2 = m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]
    s = 0.5 * math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)  # sin t
    c = 0.5 * (m[0, 0] + m[1, 1] + m[2, 2] - 1.0)  # cos t
    t = math.atan2(s, c)
    if c >= 0.0:
        if s == 0.0:
            return 0.0, 0.0, 0.0
        k = 0.5 * t / s
        return v0 * k, v1 * k, v2 * k
    k = 0  # obtuse: axis from the symmetric part
    for i in range(1, 3):
        if m[i, i] > m[k, k]:
            k = i
    a0 = 0.5 * (m[0, k] + m[k, 0]) - (c if k == 0 else 0.0)
    a1 = 0.5 * (m[1, k] + m[k, 1]) - (c if k == 1 else 0.0)
    a2 = 0.5 * (m[2, k] + m[k, 2]) - (c if k == 2 else 0.0)
    norm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    a0, a1, a2 = a0 / norm, a1 / norm, a2 / norm
    if a0 * v0 + a1 * v1 + a2 * v2 < 0.0:
        t = -t
    return t * a0, t * a1, t * a2


@numba.njit(cache=True)
def moved(q0: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """q0 (+) xi for a skeleton on a FreeJoint (DART's positions: the base's rotation vector, its
    position, then the joints): R = exp(xi_w) R0, p = p0 + xi_v, joints q0 + xi (``move``)."""
    q = np.empty(q0.shape[0])
    move(q0, xi, q)
    return q


@numba.njit(cache=True)
def move(q0: np.ndarray, xi: np.ndarray, q: np.ndarray) -> None:
    """q = q0 (+) xi (``moved``), into q, allocating nothing: the rotation's product written out."""
    for i in range(3, q0.shape[0]):
        q[i] = q0[i] + xi[i]
    a = exp_entries(xi[0], xi[1], xi[2])
    b = exp_entries(q0[0], q0[1], q0[2])
    m = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            m[i, j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j]
    q[0], q[1], q[2] = log_entries(m)
