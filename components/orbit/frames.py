"""The LVLH frame of an orbit, its angular velocity, and rotation-matrix/quaternion helpers.

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


def cross3(a, b) -> np.ndarray:
    """a × b for 3-vectors (np.cross is ~20x slower on single vectors)."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


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


def lvlh_angular_velocity(r_eci, v_eci, a_eci) -> np.ndarray:
    """Angular velocity of LVLH with respect to ECI, in ECI axes (rad/s).

    With h = r × v and LVLH axes x = r/|r|, z = h/|h|, differentiating the axes gives
        ω = (|r| (a · z) / |h|) x + (|h| / |r|^2) z,
    exactly, for any trajectory with v = dr/dt and a = dv/dt: the orbit-normal term is the
    in-plane rate, the x term the out-of-plane rotation caused by acceleration normal to the
    orbit plane (zero for two-body motion; J2 nodal drift, thrust or a custom path make it
    non-zero). There is no y component because dx/dt = (v - (v·x) x)/|r| has no z part.
    r in m, v in m/s, a in m/s^2.
    """
    return _rate(np.asarray(r_eci, dtype=np.float64), np.asarray(v_eci, dtype=np.float64),
                 np.asarray(a_eci, dtype=np.float64), lvlh_dcm(r_eci, v_eci))


def _rate(r, v, a, c) -> np.ndarray:
    x, z = c[:, 0], c[:, 2]
    h = cross3(r, v)
    r_norm, h_norm = math.sqrt(r @ r), math.sqrt(h @ h)
    return (r_norm * float(a @ z) / h_norm) * x + (h_norm / (r_norm * r_norm)) * z


def dcm_to_quat(c) -> np.ndarray:
    """Quaternion [x, y, z, w] (w >= 0) of a proper rotation matrix C_A_B -> q_A_B.

    Shepperd's method: picks the largest of 4w², 4x², 4y², 4z² to divide by, so it is
    accurate for every rotation.
    """
    m = np.asarray(c, dtype=np.float64)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    cands = (tr, m[0, 0], m[1, 1], m[2, 2])
    k = int(np.argmax(cands))
    if k == 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = np.array([(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s])
    elif k == 1:
        s = 2.0 * math.sqrt(max(1.0 + 2.0 * m[0, 0] - tr, 0.0))
        q = np.array([0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s])
    elif k == 2:
        s = 2.0 * math.sqrt(max(1.0 + 2.0 * m[1, 1] - tr, 0.0))
        q = np.array([(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s])
    else:
        s = 2.0 * math.sqrt(max(1.0 + 2.0 * m[2, 2] - tr, 0.0))
        q = np.array([(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s])
    q /= np.linalg.norm(q)
    return -q if q[3] < 0.0 else q


def quat_to_dcm(q) -> np.ndarray:
    """Rotation matrix C_A_B of a quaternion q_A_B = [x, y, z, w] (normalized first)."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def rotation_vector(c) -> np.ndarray:
    """Rotation vector (axis times angle, rad) of a proper rotation matrix C, angle in [0, pi).

    For C = exp([θ×]): θ = atan2(|s|, (tr C - 1)/2) · s/|s| with s the axial vector of
    (C - C^T)/2; accurate for small angles (as used for rates from finite differences).
    """
    m = np.asarray(c, dtype=np.float64)
    s = 0.5 * np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    sin_angle = np.linalg.norm(s)
    angle = math.atan2(sin_angle, 0.5 * (m[0, 0] + m[1, 1] + m[2, 2] - 1.0))
    if sin_angle < 1e-300:
        return np.zeros(3)
    return s * (angle / sin_angle)


def continuous(q, q_previous) -> np.ndarray:
    """q or -q (the same rotation), whichever is closer to ``q_previous``: no sign jumps in a series."""
    q = np.asarray(q, dtype=np.float64)
    if q_previous is not None and float(np.dot(q, q_previous)) < 0.0:
        return -q
    return q


def lvlh_state(r_eci, v_eci, a_eci) -> tuple[np.ndarray, np.ndarray]:
    """(q_eci_lvlh [x, y, z, w], w_lvlh in ECI axes, rad/s) from r (m), v (m/s), a (m/s^2) in ECI."""
    r = np.asarray(r_eci, dtype=np.float64)
    v = np.asarray(v_eci, dtype=np.float64)
    c = lvlh_dcm(r, v)
    return dcm_to_quat(c), _rate(r, v, np.asarray(a_eci, dtype=np.float64), c)
