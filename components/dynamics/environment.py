"""Orbital environment of a multibody in the free-falling world frame W: plain numpy functions.

W has its origin at the reference orbit point R = r_eci(t) and axes parallel to ECI; it falls
freely, so a link feels only the difference between gravity at its CoM and gravity at R.

| quantity | formula | unit |
|---|---|---|
| point-mass gravity | g(x) = -mu x / abs(x)^3 | m/s^2 |
| tidal force on link i | F_i = m_i (g(R + d_i) - g(R)), d_i = link CoM in W | N |
| gravity-gradient torque on link i | tau_i = 3 mu / abs(rho_i)^5 (rho_i x I_i rho_i), rho_i = R + d_i | N m |
| drag force on link i | F_i = -1/2 rho(h) Cd_i A_i abs(v_rel) v_rel at the CoM | N |
| third-body tidal acceleration of link i | a_3(R + d_i) - a_3(R) = g_3(R - s + d_i) - g_3(R - s), g_3(x) = -mu_3 x / abs(x)^3 | m/s^2 |

``I_i`` is the link's inertia about its CoM in W axes; ``v_rel`` is the CoM's ECI velocity
relative to an atmosphere co-rotating with the Earth (omega_E about ECI z); ``h`` the altitude
above a spherical Earth (R_E = ``R_EARTH``, 6378.137 km); ``rho(h)`` the atmosphere of
:mod:`components.space.atmosphere` (a piecewise exponential by default; NRLMSISE-00 as a local exponential).
``s`` is the Sun or the Moon from the Earth's centre, ``mu_3`` its GM (the dynamics' ``third_bodies``).
All vectors in W (= ECI) axes, SI units. The per-link evaluation in a step is
:mod:`components.dynamics.link_forces`; the functions here are the same formulas in numpy.
"""

from __future__ import annotations

import math

import numpy as np

from components.constants import MU_EARTH
from components.space.atmosphere import ExponentialAtmosphere  # noqa: F401 (the drag's atmosphere; re-exported)


def gravity(x: np.ndarray, mu: float = MU_EARTH) -> np.ndarray:
    """Point-mass gravity g(x) = -mu x / |x|^3 at position(s) x (..., 3), m/s^2."""
    x = np.asarray(x, dtype=float)
    r = np.linalg.norm(x, axis=-1, keepdims=True)
    return -mu * x / r**3


def tidal_acceleration(R: np.ndarray, delta: np.ndarray, mu: float = MU_EARTH) -> np.ndarray:
    """g(R + delta) - g(R) for offsets delta (n, 3) from the reference point R (3,), m/s^2
    (see ``tidal_force_and_gravity_gradient``)."""
    delta = np.asarray(delta, dtype=float)
    force, _ = tidal_force_and_gravity_gradient(R, delta, 1.0, None, mu, gravity_gradient=False)
    return force


def third_body_tidal_acceleration(R: np.ndarray, delta: np.ndarray, s: np.ndarray, mu3: float) -> np.ndarray:
    """The Sun's or the Moon's differential pull on points at offsets delta (n, 3) from the
    reference point R (3,), m/s^2: a_3(R + d) - a_3(R) with a_3(x) = mu3 ((s - x)/|s - x|^3 - s/|s|^3),
    the body at s (m, from the Earth's centre, same axes). The s/|s|^3 terms cancel exactly, leaving
    the Earth's tidal form about the third body: g_3(R - s + d) - g_3(R - s), evaluated without
    cancellation as ``tidal_force_and_gravity_gradient`` does. The dynamics' ``third_bodies`` apply
    it per link at every stage (``link_forces.link_third_bodies``, compiled); this is its reference."""
    return tidal_acceleration(np.asarray(R, dtype=float) - np.asarray(s, dtype=float), delta, mu3)


def gravity_gradient_torque(rho: np.ndarray, inertia_W: np.ndarray, mu: float = MU_EARTH) -> np.ndarray:
    """3 mu / |rho|^5 (rho x I rho) for rho (n, 3) from the Earth's centre and I (n, 3, 3) about
    each CoM, all in the same axes; N m about each CoM."""
    rho = np.asarray(rho, dtype=float)
    _, torque = tidal_force_and_gravity_gradient(rho, np.zeros_like(rho), 0.0, inertia_W, mu, tidal=False)
    return torque


def tidal_force_and_gravity_gradient(
    R, delta: np.ndarray, mass, inertia, mu: float = MU_EARTH, tidal: bool = True, gravity_gradient: bool = True
):
    """Tidal force m (g(R + d) - g(R)) (N) and gravity-gradient torque 3 mu / |rho|^5 (rho x I rho)
    (N m, about the CoM), rho = R + d, on n bodies of mass (n,) and inertia about their CoMs
    (n, 3, 3) at offsets d = ``delta`` (n, 3) from the reference point R: (force, torque), each
    (n, 3), zeros for a term switched off. Each body's vectors may be in its own axes: R is then
    (n, 3), the same vector in each body's axes, else (3,).

    The tidal force is written without the cancellation of subtracting two ~9 m/s^2 vectors:
    g(R+d) - g(R) = -mu [d / s^3 + R (r - s)(r^2 + r s + s^2) / (r^3 s^3)],
    r = |R|, s = |R + d|, r - s = -(2 R.d + d.d) / (r + s). Both terms share s. The dynamics
    evaluates the same formulas per link in :mod:`components.dynamics.link_forces` (compiled);
    these numpy forms are their reference.
    """
    R = np.asarray(R, dtype=float)
    d = delta
    x, y, z = R.ravel()[:3].tolist()
    r2 = x * x + y * y + z * z
    rho = R + d
    w = np.einsum("ni,ni->n", d, rho + R)  # 2 R.d + d.d = s^2 - r^2
    s2 = w + r2
    s = np.sqrt(s2)
    s3 = s2 * s
    zeros = None if tidal and gravity_gradient else np.zeros_like(d)
    force = torque = zeros
    if tidal:
        r = math.sqrt(r2)
        scale = mass / s3 * -mu
        factor = scale * w * (s + r2 / (s + r)) / (r2 * r)  # (r s + s^2 + r^2) / (r + s) = s + r^2 / (r + s)
        force = scale[:, None] * d - factor[:, None] * R
    if gravity_gradient:
        torque = (3.0 * mu / (s2 * s3))[:, None] * row_cross(rho, np.einsum("nij,nj->ni", inertia, rho))
    return force, torque


_NEXT, _PREVIOUS = np.array([1, 2, 0]), np.array([2, 0, 1])


def row_cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a x b of two (n, 3) arrays (four gathers: ~3x faster than rotations.cross for
    the few rows of a body's links)."""
    return a.take(_NEXT, axis=1) * b.take(_PREVIOUS, axis=1) - a.take(_PREVIOUS, axis=1) * b.take(_NEXT, axis=1)
