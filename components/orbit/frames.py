"""The LVLH frame of an orbit and its angular velocity (rotation helpers: :mod:`components.rotations`).

Conventions (Zenorbit contract):

- Quaternions are ``[x, y, z, w]`` (scalar last). ``q_A_B`` rotates vectors expressed in B into A;
  ``C_A_B`` is the matching 3x3 matrix, ``v_A = C_A_B @ v_B``, whose columns are B's axes in A.
- LVLH (Hill/RSW): x radial outward (r̂), z along the orbit normal r × v, y = z × x
  (along-track for a circular orbit).
- Vectors in m, m/s, m/s^2, rad/s. No bus, no I/O.
"""
from __future__ import annotations

import math

import numpy as np

from components.rotations import cross3, matrix_to_quat


def lvlh_dcm(r_eci, v_eci) -> np.ndarray:
    """C_eci_lvlh (3x3): columns are the LVLH x, y, z axes in ECI, from r (m) and v (m/s) in ECI.

    Raises ValueError if r is zero or r and v are parallel (the orbit normal is undefined).
    """
    r = np.asarray(r_eci, dtype=np.float64)
    v = np.asarray(v_eci, dtype=np.float64)
    h = cross3(r, v)
    r_norm, h_norm = math.sqrt(r @ r), math.sqrt(h @ h)
    if not r_norm > 0.0 or not h_norm > 1e-12 * r_norm * max(math.sqrt(v @ v), 1e-300):
        raise ValueError(f"LVLH undefined: expected r and v not parallel and r non-zero, got r = {r}, v = {v}")
    x = r / r_norm
    z = h / h_norm
    y = cross3(z, x)
    return np.array([x, y, z]).T


def _rate(r, v, a, c) -> np.ndarray:
    """Angular velocity of LVLH (axes ``c`` = C_eci_lvlh) with respect to ECI, in ECI axes (rad/s).

    With h = r × v and LVLH axes x = r/|r|, z = h/|h|, differentiating the axes gives
        ω = (|r| (a · z) / |h|) x + (|h| / |r|^2) z,
    exactly, for any trajectory with v = dr/dt and a = dv/dt: the orbit-normal term is the
    in-plane rate, the x term the out-of-plane rotation caused by acceleration normal to the
    orbit plane (zero for two-body motion; J2 nodal drift, thrust or a custom path make it
    non-zero). There is no y component because dx/dt = (v - (v·x) x)/|r| has no z part.
    r in m, v in m/s, a in m/s^2.
    """
    x, z = c[:, 0], c[:, 2]
    h = cross3(r, v)
    r_norm, h_norm = math.sqrt(r @ r), math.sqrt(h @ h)
    return (r_norm * float(a @ z) / h_norm) * x + (h_norm / (r_norm * r_norm)) * z


def continuous(q, q_previous) -> np.ndarray:
    """q or -q (the same rotation), whichever is closer to ``q_previous``: no sign jumps in a series."""
    q = np.asarray(q, dtype=np.float64)
    if q_previous is not None and float(np.dot(q, q_previous)) < 0.0:
        return -q
    return q


def lvlh_state(r_eci, v_eci, a_eci) -> tuple[np.ndarray, np.ndarray]:
    """(q_eci_lvlh [x, y, z, w] with w >= 0, w_lvlh in ECI axes, rad/s) from r (m), v (m/s),
    a (m/s^2) in ECI; w_lvlh is exact for any trajectory with v = dr/dt, a = dv/dt (see ``_rate``)."""
    r = np.asarray(r_eci, dtype=np.float64)
    v = np.asarray(v_eci, dtype=np.float64)
    c = lvlh_dcm(r, v)
    return matrix_to_quat(c), _rate(r, v, np.asarray(a_eci, dtype=np.float64), c)
