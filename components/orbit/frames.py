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

from components.orbit.kepler import Vector3, cross_tuples
from components.rotations import quat_of_entries


def _floats(vector) -> Vector3:
    """A 3-vector (array, list or tuple) as a tuple of floats."""
    x, y, z = vector
    return float(x), float(y), float(z)


def _lvlh_axes(r: Vector3, v: Vector3) -> tuple[Vector3, Vector3, Vector3, float, float]:
    """(x, y, z, |r|, |h|): the LVLH axes in ECI and the norms of r and h = r × v.

    Raises ValueError if r is zero or r and v are parallel (the orbit normal is undefined).
    """
    h = cross_tuples(r, v)
    r_norm = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    h_norm = math.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2])
    v_norm = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if not r_norm > 0.0 or not h_norm > 1e-12 * r_norm * max(v_norm, 1e-300):
        raise ValueError(
            f"LVLH undefined: expected r and v not parallel and r non-zero, got r = {np.array(r)}, v = {np.array(v)}"
        )
    x = (r[0] / r_norm, r[1] / r_norm, r[2] / r_norm)
    z = (h[0] / h_norm, h[1] / h_norm, h[2] / h_norm)
    return x, cross_tuples(z, x), z, r_norm, h_norm


def lvlh_dcm(r_eci, v_eci) -> np.ndarray:
    """C_eci_lvlh (3x3): columns are the LVLH x, y, z axes in ECI, from r (m) and v (m/s) in ECI.

    Raises ValueError if r is zero or r and v are parallel (the orbit normal is undefined).
    """
    x, y, z, _, _ = _lvlh_axes(_floats(r_eci), _floats(v_eci))
    return np.array((x, y, z)).T


def lvlh_state(r_eci, v_eci, a_eci) -> tuple[np.ndarray, np.ndarray]:
    """(q_eci_lvlh [x, y, z, w] with w >= 0, w_lvlh in ECI axes, rad/s) from r (m), v (m/s),
    a (m/s^2) in ECI.

    With h = r × v and LVLH axes x = r/|r|, z = h/|h|, differentiating the axes gives
        w_lvlh = (|r| (a · z) / |h|) x + (|h| / |r|^2) z,
    exactly, for any trajectory with v = dr/dt and a = dv/dt: the orbit-normal term is the
    in-plane rate, the x term the out-of-plane rotation caused by acceleration normal to the
    orbit plane (zero for two-body motion; J2 nodal drift, thrust or a custom path make it
    non-zero). There is no y component because dx/dt = (v - (v·x) x)/|r| has no z part.
    Plain floats inside: the orbit components call this every step.
    """
    q, w = lvlh_floats(_floats(r_eci), _floats(v_eci), _floats(a_eci))
    return np.array(q), np.array(w)


def lvlh_floats(r: Vector3, v: Vector3, a: Vector3) -> tuple[tuple[float, float, float, float], Vector3]:
    """:func:`lvlh_state` of three tuples of floats, as tuples of floats."""
    x, y, z, r_norm, h_norm = _lvlh_axes(r, v)
    out_of_plane = r_norm * (a[0] * z[0] + a[1] * z[1] + a[2] * z[2]) / h_norm
    in_plane = h_norm / (r_norm * r_norm)
    w = (
        out_of_plane * x[0] + in_plane * z[0],
        out_of_plane * x[1] + in_plane * z[1],
        out_of_plane * x[2] + in_plane * z[2],
    )
    return quat_of_entries(x[0], y[0], z[0], x[1], y[1], z[1], x[2], y[2], z[2]), w
