"""The arithmetic between the stages of the manifold RK4 of :mod:`components.dynamics.world`, compiled.

A stage state is q0 (+) xi with velocities v (DART order: the FreeJoint's rotation first). For
the FreeJoint the rotation moves as R = exp(xi_w) R0 at world angular velocity omega, so
d(xi_w)/dt = J_l(xi_w)^-1 omega; every other coordinate has d(xi)/dt = v. The few vector
operations per stage cost more in numpy calls (~1 us each) than in arithmetic, so they run as
two compiled functions (numba, no fastmath: IEEE arithmetic, the same bits at every run).
"""
from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True)
def so3_left_jacobian_inverse_times(phi: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """J_l(phi)^-1 omega (3,): the rate of phi for R = exp(phi) R0 turning at world angular velocity
    omega. J_l^-1 = I - [phi]x / 2 + (1 - (t/2) cot(t/2)) / t^2 [phi]x^2, t = |phi| (the
    coefficient by its series below t^2 = 1e-6, where the closed form loses digits)."""
    px, py, pz = phi[0], phi[1], phi[2]
    wx, wy, wz = omega[0], omega[1], omega[2]
    t2 = px * px + py * py + pz * pz
    if t2 < 1e-6:
        c = 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0
    else:
        t = math.sqrt(t2)
        c = (1.0 - 0.5 * t / math.tan(0.5 * t)) / t2
    cx, cy, cz = py * wz - pz * wy, pz * wx - px * wz, px * wy - py * wx          # phi x omega
    dx, dy, dz = py * cz - pz * cy, pz * cx - px * cz, px * cy - py * cx          # phi x (phi x omega)
    return np.array([wx - 0.5 * cx + c * dx, wy - 0.5 * cy + c * dy, wz - 0.5 * cz + c * dz])


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
