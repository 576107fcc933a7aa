"""The orbital environment on one link, compiled: the terms both engines' loops over the links share.

The formulas are those of :mod:`components.dynamics.environment` (tidal force, gravity-gradient
torque, drag, the Sun's and the Moon's tidal force) and of :mod:`components.space.srp` and
:mod:`components.space.eclipse` (solar radiation pressure), evaluated per link:
``link_environment`` (tidal force and gravity-gradient torque, in whichever axes its vectors are
given), ``link_third_bodies`` (the same tidal form about the Sun and the Moon), ``drag_factor`` and
``link_srp``; and the reference point each stage evaluates them about, ``propagate_reference``.
They run at each of the four rk4 stages of every step; written with numpy they cost ~60 us a stage
in ~40 calls on arrays of a few rows, so the loops over the links are compiled with numba
(nopython, no fastmath: IEEE arithmetic, the same bits on every run on a machine).
``tests/unit/test_dynamics_world.py`` and ``test_dynamics_pinocchio.py`` check them against
DART's and Pinocchio's own handling of the same per-link wrenches.

The loops themselves, one per engine, give generalized forces in the world's coordinates (the
base's rotation, then its origin, then the joints; forces dual to the world-frame angular velocity
and the base origin's velocity):

- :mod:`components.dynamics.anchor_forces` (DART): the links in their anchor's axes, mapped
  through the anchors' body Jacobians;
- :mod:`components.dynamics.tree_forces` (Pinocchio): the joint frames by forward kinematics over
  the model's tree, the links in W axes, and the joint forces by a backward pass over the tree.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from components.space.eclipse import illumination_nb
from components.space.srp import cannonball_nb, facets_nb

# ``light`` (LIGHT_SIZE,): the Sun for SRP: pressure at 1 AU (N/m^2), AU (m), eclipse model
# (components.space.eclipse), radii of the Sun, Earth, Moon (m), the Moon shades (1) or not (0),
# Sun and Moon from the Earth's centre (m, W axes)
LIGHT_SIZE = 13
SUN, MOON = 7, 10  # where the Sun's and the Moon's positions start in ``light`` (also the third bodies')


@numba.njit(cache=True)
def link_srp(x, local_T, light, cr_area, facets, s_W, s_local, f, t):
    """Adds to ``f`` (N, at the CoM) and ``t`` (N m, about it) the solar radiation pressure on a
    link whose CoM is at ``x`` (m from the Earth's centre, W): cannonball (Cr A = ``cr_area``) and
    ``facets`` (rows of components.space.srp, in the link's local axes, centres from its CoM);
    ``local_T`` (3, 3) turns W into those axes. ``s_W``, ``s_local``: scratch (3,)."""
    nu = illumination_nb(x, light[7:10], light[10:13], light[6] != 0.0, int(light[2]), light[3], light[4], light[5])
    if nu <= 0.0:
        return
    for i in range(3):
        s_W[i] = light[7 + i] - x[i]  # CoM -> Sun
    rotate(local_T, s_W, s_local)
    if cr_area > 0.0:
        cannonball_nb(s_local, cr_area, light[0], light[1], nu, f)
    if facets.shape[0]:
        facets_nb(s_local, facets, light[0], light[1], nu, f, t)


@numba.njit(cache=True)
def link_environment(R, d, mass, inertia, r2, r, mu, tidal, gravity_gradient, f, t):
    """Tidal force ``f`` (at the CoM) and gravity-gradient torque ``t`` (about it) of one link, all
    in one set of axes: R the reference point from the Earth's centre, d the link's CoM from R,
    inertia about the CoM, r2 = |R|^2, r = |R|. A term switched off is left zero.

    m (g(R + d) - g(R)) = -mu m [d / s^3 + R (r - s)(r^2 + r s + s^2) / (r^3 s^3)], s = |R + d|,
    r - s = -(2 R.d + d.d) / (r + s): no cancellation of two ~9 m/s^2 vectors;
    torque 3 mu / s^5 (rho x I rho), rho = R + d."""
    rho0, rho1, rho2 = R[0] + d[0], R[1] + d[1], R[2] + d[2]
    w = 0.0
    w += d[0] * (rho0 + R[0])  # 2 R.d + d.d = s^2 - r^2
    w += d[1] * (rho1 + R[1])
    w += d[2] * (rho2 + R[2])
    s2 = w + r2
    s = math.sqrt(s2)
    s3 = s2 * s
    f[0], f[1], f[2] = 0.0, 0.0, 0.0
    t[0], t[1], t[2] = 0.0, 0.0, 0.0
    if tidal:
        scale = mass / s3 * -mu
        factor = scale * w * (s + r2 / (s + r)) / (r2 * r)  # (r s + s^2 + r^2) / (r + s) = s + r^2 / (r + s)
        for i in range(3):
            f[i] = scale * d[i] - factor * R[i]
    if gravity_gradient:
        i0 = inertia[0, 0] * rho0 + inertia[0, 1] * rho1 + inertia[0, 2] * rho2
        i1 = inertia[1, 0] * rho0 + inertia[1, 1] * rho1 + inertia[1, 2] * rho2
        i2 = inertia[2, 0] * rho0 + inertia[2, 1] * rho1 + inertia[2, 2] * rho2
        g = 3.0 * mu / (s2 * s3)
        t[0] = g * (rho1 * i2 - rho2 * i1)
        t[1] = g * (rho2 * i0 - rho0 * i2)
        t[2] = g * (rho0 * i1 - rho1 * i0)


@numba.njit(cache=True)
def link_third_bodies(R, d, mass, inertia, third, light, rotation_T, rel, f3, t3, f):
    """Adds to ``f`` (N, at the CoM) the Sun's and the Moon's tidal force on a link of ``mass`` (kg)
    whose CoM is at ``d`` from the reference point, in the axes ``rotation_T`` (3, 3) turns W into
    (``R``: the reference point from the Earth's centre in W): for each body b with GM
    ``third[b]`` > 0 at s_b (``light``, W), m (g_b(R - s_b + d) - g_b(R - s_b)), g_b(x) =
    -mu_b x / abs(x)^3: ``link_environment``'s tidal form about the body, without cancellation.
    ``rel``, ``f3``, ``t3``: scratch (3,)."""
    for b in range(2):
        mu3 = third[b]
        if mu3 > 0.0:
            start = SUN if b == 0 else MOON
            x0, x1, x2 = R[0] - light[start], R[1] - light[start + 1], R[2] - light[start + 2]  # R - s_b, W
            r2 = x0 * x0 + x1 * x1 + x2 * x2
            for i in range(3):
                rel[i] = rotation_T[i, 0] * x0 + rotation_T[i, 1] * x1 + rotation_T[i, 2] * x2
            link_environment(rel, d, mass, inertia, r2, math.sqrt(r2), mu3, True, False, f3, t3)
            for i in range(3):
                f[i] += f3[i]


@numba.njit(cache=True)
def drag_factor(x, V, v_com, drag_k, h0, rho0, scale_height, earth_rate, earth_radius, v_rel):
    """Drag on a link whose CoM is at x (from the Earth's centre, W) moving at V + v_com (W):
    fills ``v_rel``, the velocity against an atmosphere turning with the Earth (W), and returns c
    with the force c v_rel = -1/2 rho(h) Cd A |v_rel| v_rel."""
    v_rel[0] = V[0] + v_com[0] + earth_rate * x[1]
    v_rel[1] = V[1] + v_com[1] - earth_rate * x[0]
    v_rel[2] = V[2] + v_com[2]
    altitude = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) - earth_radius
    band = 0
    while band + 1 < h0.shape[0] and h0[band + 1] <= altitude:
        band += 1
    density = rho0[band] * math.exp(-(altitude - h0[band]) / scale_height[band])
    speed = math.sqrt(v_rel[0] * v_rel[0] + v_rel[1] * v_rel[1] + v_rel[2] * v_rel[2])
    return -density * drag_k * speed


@numba.njit(cache=True)
def propagate_reference(R0, V0, s, mu):
    """Two-body reference point (R, V) after s seconds from (R0, V0) (m, m/s, s, m^3/s^2), by its
    Taylor series to third order in s: R(s) = R0 + V0 s + g s^2/2 + j s^3/6, V(s) = V0 + g s + j s^2/2
    with g = g(R0) and the jerk j = -mu/r^3 (V0 - 3 (R0.V0) R0 / r^2). Position error
    ~ (mu/r^3)^2 r s^4 / 24 (5 mm at s = 10 s in LEO). Used inside a communication step, where the
    orbit inputs are held."""
    if s == 0.0:
        return R0.copy(), V0.copy()
    x, y, z = R0[0], R0[1], R0[2]
    u, v, w = V0[0], V0[1], V0[2]
    r2 = x * x + y * y + z * z
    k = mu / (r2 * math.sqrt(r2))
    c = 3.0 * (x * u + y * v + z * w) / r2
    gx, gy, gz = -k * x, -k * y, -k * z
    jx, jy, jz = -k * (u - c * x), -k * (v - c * y), -k * (w - c * z)
    a, b = 0.5 * s, s / 6.0
    return (
        np.array(
            [
                x + s * (u + s * (0.5 * gx + b * jx)),
                y + s * (v + s * (0.5 * gy + b * jy)),
                z + s * (w + s * (0.5 * gz + b * jz)),
            ]
        ),
        np.array([u + s * (gx + a * jx), v + s * (gy + a * jy), w + s * (gz + a * jz)]),
    )


@numba.njit(cache=True)
def rotate(A, b, out):
    """out = A b (3x3 by 3)."""
    for i in range(3):
        out[i] = A[i, 0] * b[0] + A[i, 1] * b[1] + A[i, 2] * b[2]


@numba.njit(cache=True)
def cross(a, b, out):
    """out = a x b (3-vectors)."""
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
