"""Rotations and small vector helpers shared by every component: plain numpy, no bus, no I/O.

Conventions (Zenorbit contract, docs/design.md §2):

- Quaternions are ``[x, y, z, w]`` (scalar last, as SciPy's ``Rotation``, ROS, Rerun, Pinocchio).
  ``q_A_B`` rotates vectors expressed in B into A; ``R_A_B`` (or ``C_A_B``) is the matching 3x3
  matrix, ``v_A = R_A_B @ v_B``, whose columns are B's axes in A.
- A rotation vector ``phi`` (axis times angle, rad) and its matrix are related by
  ``R = exp_so3(phi)`` (Rodrigues) and ``phi = log_so3(R)``.
- URDF ``rpy``: ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

``quat_to_matrix`` and ``matrix_to_quat`` take one rotation or a batch (``(..., 4)`` /
``(..., 3, 3)``); a single rotation takes a scalar fast path. ``cross3`` (one pair of 3-vectors)
and ``cross`` (row-wise, broadcasting) are there because ``np.cross`` is ~20x slower on small
inputs and the dynamics calls them in its integration loop.
"""

from __future__ import annotations

import math

import numpy as np

# --------------------------------------------------------------------------- vectors


def cross3(a, b) -> np.ndarray:
    """a × b for one pair of 3-vectors (np.cross is ~20x slower on single vectors)."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a × b of (..., 3) arrays, broadcasting (np.cross without its axis handling overhead)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def skew(w) -> np.ndarray:
    """The 3x3 matrix [w]x with [w]x v = w × v."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


# --------------------------------------------------------------------------- quaternions


def quat_to_matrix(q) -> np.ndarray:
    """Rotation matrix R_A_B of a quaternion q_A_B = [x, y, z, w], normalized first.

    ``q`` is one quaternion (4,) -> (3, 3), or a batch (..., 4) -> (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    if q.ndim == 1:
        x, y, z, w = q / np.linalg.norm(q)
        return np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
    x, y, z, w = np.moveaxis(q / np.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)
    R[..., 1, 0], R[..., 1, 1], R[..., 1, 2] = 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)
    R[..., 2, 0], R[..., 2, 1], R[..., 2, 2] = 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)
    return R


def matrix_entries_to_quat(
    m00: float, m01: float, m02: float, m10: float, m11: float, m12: float, m20: float, m21: float, m22: float
) -> np.ndarray:
    """``matrix_to_quat`` of one rotation given as its nine entries (row-major floats): the fast
    path for per-step callers, with no 3x3 array to build."""
    return np.array(quat_of_entries(m00, m01, m02, m10, m11, m12, m20, m21, m22))


def quat_of_entries(
    m00: float, m01: float, m02: float, m10: float, m11: float, m12: float, m20: float, m21: float, m22: float
) -> tuple[float, float, float, float]:
    """``matrix_entries_to_quat`` as four floats, for a caller that builds one array of them and more."""
    d = (1.0 + m00 - m11 - m22, 1.0 - m00 + m11 - m22, 1.0 - m00 - m11 + m22, 1.0 + m00 + m11 + m22)
    k = d.index(max(d))
    if k == 0:
        q = (d[0], m01 + m10, m02 + m20, m21 - m12)
    elif k == 1:
        q = (m01 + m10, d[1], m12 + m21, m02 - m20)
    elif k == 2:
        q = (m02 + m20, m12 + m21, d[2], m10 - m01)
    else:
        q = (m21 - m12, m02 - m20, m10 - m01, d[3])
    scale = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    scale = -scale if q[3] < 0.0 else scale
    return q[0] * scale, q[1] * scale, q[2] * scale, q[3] * scale


def matrix_to_quat(R) -> np.ndarray:
    """Unit quaternion q_A_B = [x, y, z, w] of a rotation matrix R_A_B, with **w >= 0**.

    ``R`` is one matrix (3, 3) -> (4,), or a batch (..., 3, 3) -> (..., 4).

    Sign convention: q and -q are the same rotation; this returns the one with w >= 0 (for a
    half turn, w = 0, the sign is that of the largest of |x|, |y|, |z|). Callers that need a
    sign-continuous series flip it themselves (``continuous``).

    Shepperd's method: with A the symmetric 4x4 matrix whose row k is 4 q_k q, the row with the
    largest diagonal entry 4 q_k^2 is used (no small divisor, accurate for every rotation), and
    normalized (so a slightly non-orthonormal R still gives a unit quaternion).
    """
    R = np.asarray(R, dtype=float)
    if R.shape == (3, 3):
        return matrix_entries_to_quat(*R.ravel().tolist())
    m = R.reshape(-1, 3, 3)
    n = m.shape[0]
    A = np.empty((n, 4, 4))
    m00, m11, m22 = m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]
    A[:, 0, 0] = 1.0 + m00 - m11 - m22
    A[:, 1, 1] = 1.0 - m00 + m11 - m22
    A[:, 2, 2] = 1.0 - m00 - m11 + m22
    A[:, 3, 3] = 1.0 + m00 + m11 + m22
    A[:, 0, 1] = A[:, 1, 0] = m[:, 0, 1] + m[:, 1, 0]
    A[:, 0, 2] = A[:, 2, 0] = m[:, 0, 2] + m[:, 2, 0]
    A[:, 1, 2] = A[:, 2, 1] = m[:, 1, 2] + m[:, 2, 1]
    A[:, 0, 3] = A[:, 3, 0] = m[:, 2, 1] - m[:, 1, 2]
    A[:, 1, 3] = A[:, 3, 1] = m[:, 0, 2] - m[:, 2, 0]
    A[:, 2, 3] = A[:, 3, 2] = m[:, 1, 0] - m[:, 0, 1]
    rows = np.arange(n)
    k = np.argmax(A[:, [0, 1, 2, 3], [0, 1, 2, 3]], axis=1)
    q = A[rows, k]
    q /= np.linalg.norm(q, axis=1, keepdims=True) * np.where(q[:, 3:4] < 0.0, -1.0, 1.0)
    return q.reshape(R.shape[:-2] + (4,))


def opposite(a, b) -> bool:
    """Whether quaternions ``a`` and ``b`` (four floats each) lie in opposite hemispheres (a . b < 0):
    the sign test of ``continuous``, for per-step callers holding plain floats."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] < 0.0


def continuous(q, q_previous) -> np.ndarray:
    """q with the sign of each of its quaternions (every 4 values, [x, y, z, w]) chosen closer to
    the same quaternion of ``q_previous`` (q and -q are the same rotation): no sign jumps from one
    sample of a series to the next. ``q_previous`` None: q as given. Returns a new array."""
    q = np.array(q, dtype=np.float64)
    if q_previous is None:
        return q
    if q.size == 4:  # the common case, in plain floats (a step's budget is microseconds)
        a = q.tolist()
        b = (
            q_previous.tolist()
            if q_previous.__class__ is np.ndarray
            else np.asarray(q_previous, dtype=np.float64).tolist()
        )
        if opposite(a, b):
            q *= -1.0
        return q
    quats = q.reshape(-1, 4)
    quats[np.einsum("ij,ij->i", quats, np.reshape(q_previous, (-1, 4))) < 0.0] *= -1.0
    return q


# --------------------------------------------------------------------------- rotation vectors (SO(3))


def exp_so3(phi) -> np.ndarray:
    """Rotation matrix of a rotation vector phi (axis times angle, rad): Rodrigues' formula.

    For a unit ``axis`` and an ``angle``, ``exp_so3(angle * axis)`` is the axis-angle matrix."""
    phi = np.asarray(phi, dtype=float)
    t = float(np.linalg.norm(phi))
    K = skew(phi)
    if t < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + math.sin(t) / t * K + (1.0 - math.cos(t)) / (t * t) * K @ K


def log_so3(R) -> np.ndarray:
    """Rotation vector (axis times angle, rad) of a rotation matrix R, angle in [0, pi].

    The angle is t = atan2(|v|/2, (tr R - 1)/2) with v the axial vector of R - R^T (= 2 sin t
    axis): accurate to rounding for every angle. The axis is v/|v| when cos t >= 0; for obtuse
    angles it comes from the symmetric part, axis axis^T = ((R + R^T)/2 - cos t I) / (1 - cos t),
    whose accuracy does not degrade as sin t -> 0 (the sign from v; at t = pi exactly both signs
    are the same rotation and either may be returned).
    """
    m = np.asarray(R, dtype=float)
    v = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    s = 0.5 * math.sqrt(float(v @ v))  # sin t
    c = 0.5 * (m[0, 0] + m[1, 1] + m[2, 2] - 1.0)  # cos t
    t = math.atan2(s, c)
    if c >= 0.0:
        if s == 0.0:
            return np.zeros(3)
        return v * (0.5 * t / s)
    S = 0.5 * (m + m.T) - c * np.eye(3)  # (1 - cos t) axis axis^T
    k = int(np.argmax(np.diag(S)))
    axis = S[:, k] / math.sqrt(S[k, k])
    axis /= np.linalg.norm(axis)
    if float(axis @ v) < 0.0:
        axis = -axis
    return t * axis


# --------------------------------------------------------------------------- URDF roll-pitch-yaw


def rpy_to_matrix(rpy) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) of rpy = (roll, pitch, yaw) in rad (URDF convention)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def matrix_to_rpy(R) -> tuple[float, float, float]:
    """Inverse of :func:`rpy_to_matrix`: (roll, pitch, yaw), rad (any valid solution at pitch = +-90 deg)."""
    cp = math.hypot(R[0, 0], R[1, 0])
    pitch = math.atan2(-R[2, 0], cp)
    if cp > 1e-9:
        roll = math.atan2(R[2, 1], R[2, 2])
        yaw = math.atan2(R[1, 0], R[0, 0])
    else:  # gimbal lock: put everything in roll
        yaw = 0.0
        roll = math.atan2(-R[1, 2], R[1, 1])
    return roll, pitch, yaw
