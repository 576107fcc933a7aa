"""The orbital environment on a body's links, as generalized forces: compiled loops, one per engine.

The formulas are those of :mod:`components.dynamics.environment` (tidal force, gravity-gradient
torque, drag, the Sun's and the Moon's tidal force) and of :mod:`components.space.srp` and
:mod:`components.space.eclipse` (solar radiation pressure), evaluated per link by the functions
both engines share, ``link_environment`` (tidal force and gravity-gradient torque, in whichever
axes its vectors are given), ``link_third_bodies`` (the same tidal form about the Sun and the
Moon), ``drag_factor`` and ``link_srp``. They run at each of the four rk4 stages of every step; written with numpy they
cost ~60 us a stage in ~40 calls on arrays of a few rows, so the loops over the links are
compiled with numba (nopython, no fastmath: IEEE arithmetic, the same bits on every run on a
machine). ``tests/unit/test_dynamics_world.py`` and ``test_dynamics_pinocchio.py`` check them
against DART's and Pinocchio's own handling of the same per-link wrenches.

Two ways to generalized forces, in the world's coordinates (the base's rotation, then its origin,
then the joints; forces dual to the world-frame angular velocity and the base origin's velocity):

- ``generalized_forces`` (DART): the links in their anchor's axes (a link welded to its parent
  moves with the nearest ancestor that is not welded: its anchor), mapped through the anchors'
  body Jacobians (Q = sum_a J_a^T W_a), which also give the anchors' poses;
- ``tree_generalized_forces`` (Pinocchio): the joint frames by forward kinematics over the
  model's tree, the links in W axes, and the joint forces by a backward pass over the tree
  (Q_j = s_j . the wrench of everything beyond joint j).

Inputs of ``generalized_forces`` (all float64 or int64 arrays, SI units):

| argument | shape | meaning |
|---|---|---|
| J | (6, c) | the anchors' body Jacobians side by side, [angular; linear], anchor axes |
| rotation_columns | (k, 3) | columns of J that hold the base rotation dofs of each anchor |
| jacobian_anchor, jacobian_dofs | (c,) | anchor and dof of each column of J |
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
| tau | (ndofs,) | joint generalized forces (added to the result) |
| force, torque | (n, 3) | filled with each link's environment force at its CoM and torque about it, anchor axes |
| srp, light | -, (13,) | solar radiation pressure on or off; the Sun (``LIGHT_SIZE``, below) |
| srp_links | (n, 3) | per link: Cr A (m^2, 0: no cannonball), first row and count of its facets |
| facets | (m, 9) | facets (components.space.srp), anchor axes, centres from the link's CoM (m) |
| third | (2,) | GM of the Sun, of the Moon (m^3/s^2) whose tidal force acts; 0: that body off (their positions: ``light``) |

Frames: the base rotation columns of anchor a's Jacobian are R_a^T (angular rows) and
-[o_a]x R_a^T (linear rows), with o_a = R_a^T (p_a - p) the anchor origin relative to the base
origin p in anchor axes: one Jacobian gives the anchor's pose too.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from components.dynamics.manifold_rk4 import exp_entries
from components.space.eclipse import illumination_nb
from components.space.srp import cannonball_nb, facets_nb

REVOLUTE, PRISMATIC = 1, 2  # tree joint kinds (0: the free base)
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
    _rotate(local_T, s_W, s_local)
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
def generalized_forces(
    J,
    rotation_columns,
    jacobian_anchor,
    jacobian_dofs,
    anchor_slot,
    com,
    inertia,
    mass,
    R,
    V,
    base,
    mu,
    tidal,
    gravity_gradient,
    drag,
    drag_k,
    v_com,
    h0,
    rho0,
    scale_height,
    earth_rate,
    earth_radius,
    tau,
    force,
    torque,
    srp,
    light,
    srp_links,
    facets,
    third,
):
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
            base_local[a, i] = value  # o_a for now
        for i in range(3):
            r_i, b_i = 0.0, 0.0
            for j in range(3):
                r_i += rotation_T[a, i, j] * R[j]
                b_i += rotation_T[a, i, j] * base[j]
            R_local[a, i] = r_i
            base_local[a, i] += b_i  # R_a^T p + o_a: the anchor origin in W, anchor axes
    r2 = R[0] * R[0] + R[1] * R[1] + R[2] * R[2]
    r = math.sqrt(r2)
    wrench = np.zeros((k, 6))  # per anchor, about its origin: [torque; force]
    d = np.empty(3)
    f = np.empty(3)
    t = np.empty(3)
    x = np.empty(3)
    v_rel = np.empty(3)
    lever = np.empty(3)
    third_on = third[0] > 0.0 or third[1] > 0.0
    for n in range(anchor_slot.shape[0]):
        a = anchor_slot[n]
        for i in range(3):
            d[i] = base_local[a, i] + com[n, i]  # link CoM from the reference point
        link_environment(R_local[a], d, mass[n], inertia[n], r2, r, mu, tidal, gravity_gradient, f, t)
        if third_on:
            link_third_bodies(R, d, mass[n], inertia[n], third, light, rotation_T[a], x, v_rel, lever, f)
        if drag and drag_k[n] > 0.0:
            for i in range(3):
                x[i] = R[i]
                for j in range(3):
                    x[i] += rotation_T[a, j, i] * d[j]
            c = drag_factor(x, V, v_com[n], drag_k[n], h0, rho0, scale_height, earth_rate, earth_radius, v_rel)
            for i in range(3):
                value = 0.0
                for j in range(3):
                    value += rotation_T[a, i, j] * v_rel[j]
                f[i] += c * value
        if srp and (srp_links[n, 0] > 0.0 or srp_links[n, 2] > 0.0):
            for i in range(3):
                x[i] = R[i]
                for j in range(3):
                    x[i] += rotation_T[a, j, i] * d[j]
            start = int(srp_links[n, 1])
            link_srp(
                x,
                rotation_T[a],
                light,
                srp_links[n, 0],
                facets[start : start + int(srp_links[n, 2])],
                v_rel,
                lever,
                f,
                t,
            )
        force[n, 0], force[n, 1], force[n, 2] = f[0], f[1], f[2]
        torque[n, 0], torque[n, 1], torque[n, 2] = t[0], t[1], t[2]
        c0, c1, c2 = com[n, 0], com[n, 1], com[n, 2]
        wrench[a, 0] += t[0] + c1 * f[2] - c2 * f[1]
        wrench[a, 1] += t[1] + c2 * f[0] - c0 * f[2]
        wrench[a, 2] += t[2] + c0 * f[1] - c1 * f[0]
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


@numba.njit(cache=True)
def _rotate(A, b, out):
    """out = A b (3x3 by 3)."""
    for i in range(3):
        out[i] = A[i, 0] * b[0] + A[i, 1] * b[1] + A[i, 2] * b[2]


@numba.njit(cache=True)
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@numba.njit(cache=True)
def _axis_rotation(u, angle, out):
    """out = exp([u]x angle) for a unit axis u: cos I + sin [u]x + (1 - cos) u u^T (1 - cos as
    2 sin^2(angle / 2): no cancellation at small angles)."""
    c, s = math.cos(angle), math.sin(angle)
    h = math.sin(0.5 * angle)
    k = 2.0 * h * h
    for i in range(3):
        for j in range(3):
            out[i, j] = k * u[i] * u[j]
        out[i, i] += c
    out[0, 1] -= s * u[2]
    out[1, 0] += s * u[2]
    out[0, 2] += s * u[1]
    out[2, 0] -= s * u[1]
    out[1, 2] -= s * u[0]
    out[2, 1] += s * u[0]


@numba.njit(cache=True)
def tree_kinematics(x, v, joints, frames, with_velocity, rotation, position, joint_axis, angular, linear, work):
    """Joint frames in W over a tree whose joint 1 is the free base, from the world's coordinates
    x, v (base rotation vector, base origin, joints): ``rotation``, ``position`` (nj, 3, 3),
    (nj, 3); ``joint_axis`` (nj, 3), W; with ``with_velocity`` also each joint frame's
    ``angular`` velocity and its origin's ``linear`` one (W). ``joints`` (nj, 3): parent, kind
    (REVOLUTE, PRISMATIC; 0 for the base), coordinate; ``frames`` (nj, 15): the joint's placement
    in its parent's frame (rotation row-major, translation), its axis in its own frame. Parents
    come first. ``work``: 24 floats of scratch."""
    m = exp_entries(x[0], x[1], x[2])
    for r in range(3):
        rotation[1, r, 0], rotation[1, r, 1], rotation[1, r, 2] = m[3 * r], m[3 * r + 1], m[3 * r + 2]
    position[1] = x[3:6]
    if with_velocity:
        angular[1] = v[0:3]
        linear[1] = v[3:6]
    matrices = work[:18].reshape((2, 3, 3))
    Rj, E = matrices[0], matrices[1]
    vectors = work[18:24].reshape((2, 3))
    lever, w_x_lever = vectors[0], vectors[1]
    for j in range(2, joints.shape[0]):
        p, kind, k = joints[j, 0], joints[j, 1], joints[j, 2]
        f = frames[j]
        Rp = rotation[p]
        for r in range(3):  # Rj = R_p placement_R, origin = R_p placement_p + p_p
            for c in range(3):
                Rj[r, c] = Rp[r, 0] * f[c] + Rp[r, 1] * f[3 + c] + Rp[r, 2] * f[6 + c]
            position[j, r] = Rp[r, 0] * f[9] + Rp[r, 1] * f[10] + Rp[r, 2] * f[11] + position[p, r]
        u = joint_axis[j]
        _rotate(Rj, f[12:15], u)
        value = x[k]
        if kind == REVOLUTE:
            _axis_rotation(f[12:15], value, E)
            for r in range(3):
                for c in range(3):
                    rotation[j, r, c] = Rj[r, 0] * E[0, c] + Rj[r, 1] * E[1, c] + Rj[r, 2] * E[2, c]
        else:
            rotation[j] = Rj
            for r in range(3):
                position[j, r] += u[r] * value
        if with_velocity:
            rate = v[k]
            for r in range(3):
                lever[r] = position[j, r] - position[p, r]
            _cross(angular[p], lever, w_x_lever)
            for r in range(3):
                angular[j, r] = angular[p, r] + (u[r] * rate if kind == REVOLUTE else 0.0)
                linear[j, r] = linear[p, r] + w_x_lever[r] + (u[r] * rate if kind == PRISMATIC else 0.0)


@numba.njit(cache=True)
def tree_generalized_forces(
    x,
    v,
    tau,
    joints,
    frames,
    links,
    link_joint,
    R,
    V,
    mu,
    tidal,
    gravity_gradient,
    drag,
    atmosphere,
    earth_rate,
    earth_radius,
    force,
    torque,
    srp,
    light,
    facets,
    third,
):
    """``tau`` plus the environment's generalized forces (world coordinates) of a body given as a
    tree (``joints``, ``frames``: see ``tree_kinematics``). Links: ``links`` (n, 17) their CoM (3)
    and inertia about it (9, row-major) in their joint's frame, mass, 1/2 Cd A, then for SRP (with
    ``srp``: ``link_srp``, ``light``) Cr A and their first row and count in ``facets`` (joint's
    axes, centres from the CoM); ``link_joint``
    (n,) their joint. ``atmosphere`` (3, b): the bands' base altitude, density, scale height.
    Fills ``force``, ``torque`` (n, 3): each link's environment force at its CoM and torque about
    it, W axes."""
    nj = joints.shape[0]
    block = np.zeros(27 * nj + 63)  # one allocation (a call's few microseconds count)
    per_joint = block[: 18 * nj].reshape((6, nj, 3))
    rotation = block[18 * nj : 27 * nj].reshape((nj, 3, 3))
    position, joint_axis, angular, linear = per_joint[0], per_joint[1], per_joint[2], per_joint[3]
    total_force, total_torque = per_joint[4], per_joint[5]  # per joint: its links' wrench about the W origin
    tree_kinematics(x, v, joints, frames, drag, rotation, position, joint_axis, angular, linear, block[27 * nj + 39 :])
    r2 = R[0] * R[0] + R[1] * R[1] + R[2] * R[2]
    r = math.sqrt(r2)
    scratch = block[27 * nj : 27 * nj + 39].reshape((13, 3))
    f, t, d, c_W, v_rel, x_earth, v_com, lever = (
        scratch[0],
        scratch[1],
        scratch[2],
        scratch[3],
        scratch[4],
        scratch[5],
        scratch[6],
        scratch[7],
    )
    about, R_local, d_local, f_local, t_local = scratch[8], scratch[9], scratch[10], scratch[11], scratch[12]
    third_on = third[0] > 0.0 or third[1] > 0.0
    for n in range(link_joint.shape[0]):
        j = link_joint[n]
        Rj = rotation[j]
        link = links[n]
        _rotate(Rj, link[0:3], c_W)
        for i in range(3):
            d[i] = c_W[i] + position[j, i]  # CoM from the reference point, W
        for i in range(3):  # R and d in the joint's frame, where the inertia is given
            R_local[i] = Rj[0, i] * R[0] + Rj[1, i] * R[1] + Rj[2, i] * R[2]
            d_local[i] = Rj[0, i] * d[0] + Rj[1, i] * d[1] + Rj[2, i] * d[2]
        inertia = link[3:12].reshape((3, 3))
        link_environment(R_local, d_local, link[12], inertia, r2, r, mu, tidal, gravity_gradient, f_local, t_local)
        if third_on:
            link_third_bodies(R, d_local, link[12], inertia, third, light, Rj.T, x_earth, v_rel, lever, f_local)
        if srp and (link[14] > 0.0 or link[16] > 0.0):
            for i in range(3):
                x_earth[i] = R[i] + d[i]
            start = int(link[15])
            link_srp(
                x_earth, Rj.T, light, link[14], facets[start : start + int(link[16])], v_rel, lever, f_local, t_local
            )
        _rotate(Rj, f_local, f)
        _rotate(Rj, t_local, t)
        if drag and link[13] > 0.0:
            _cross(angular[j], c_W, lever)
            for i in range(3):
                v_com[i] = linear[j, i] + lever[i]
                x_earth[i] = R[i] + d[i]
            c = drag_factor(
                x_earth,
                V,
                v_com,
                link[13],
                atmosphere[0],
                atmosphere[1],
                atmosphere[2],
                earth_rate,
                earth_radius,
                v_rel,
            )
            for i in range(3):
                f[i] += c * v_rel[i]
        for i in range(3):
            force[n, i] = f[i]
            torque[n, i] = t[i]
            total_force[j, i] += f[i]
        total_torque[j, 0] += t[0] + d[1] * f[2] - d[2] * f[1]
        total_torque[j, 1] += t[1] + d[2] * f[0] - d[0] * f[2]
        total_torque[j, 2] += t[2] + d[0] * f[1] - d[1] * f[0]
    for j in range(nj - 1, 1, -1):  # children before parents
        for i in range(3):
            total_force[joints[j, 0], i] += total_force[j, i]
            total_torque[joints[j, 0], i] += total_torque[j, i]
    out = tau.copy()
    for j in range(1, nj):
        F, T = total_force[j], total_torque[j]
        _cross(position[j], F, about)
        for i in range(3):
            about[i] = T[i] - about[i]  # about the joint's origin
        if j == 1:
            for i in range(3):
                out[i] += about[i]
                out[3 + i] += F[i]
        elif joints[j, 1] == REVOLUTE:
            u = joint_axis[j]
            out[joints[j, 2]] += u[0] * about[0] + u[1] * about[1] + u[2] * about[2]
        else:
            u = joint_axis[j]
            out[joints[j, 2]] += u[0] * F[0] + u[1] * F[1] + u[2] * F[2]
    return out
