"""The compiled kernels of :mod:`components.dynamics.pinocchio_body`: the conversions between the
world's coordinates and Pinocchio's (see that module's docstring), and the RK4 evaluations of a
body that steps itself (``rk4_begin``, ``rk4_evaluation``: one call per evaluation, the stage
arithmetic, the environment and Pinocchio's inputs in it; a call's cost grows with its arguments,
so the body's arrays come in two pools, ``unpool``), and a rigid body's (no joints) whole step in
one call without Pinocchio (``rk4_rigid``). numba, no fastmath: IEEE arithmetic, the same bits at
every run.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from components.dynamics import link_forces, manifold_rk4

LINK_COLUMNS = 17  # a link's row: CoM (3), inertia (9), mass, 1/2 Cd A, Cr A, first facet, facets
# mu, Earth's rate, radius, tidal, gravity gradient, drag, SRP; light; the GMs of the third bodies (Sun, Moon; 0: off)
LIGHT = 7
THIRD = LIGHT + link_forces.LIGHT_SIZE
CONSTANTS = THIRD + 2


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
def form_stage(stage, c, a, q0, v0, work, x, v):
    """The RK4 stage ``stage`` (1 to 3) from the step's start (q0, v0) and the last stage's
    derivatives, or with ``stage`` 4 the step's end (h = c); into x, v. ``work`` (10, n) holds the
    rates of stages 2 to 4 (rows 0-2, each written here), the accelerations a1 to a4 (rows 3-6:
    ``a``, the last stage's, is written here) and xi (row 7; rows 8, 9: ``rk4_begin``'s). The
    arithmetic of ``manifold_rk4.stage`` and ``combine``, in the same order (the same bits)."""
    n = v0.shape[0]
    work[2 + stage] = a
    xi = work[7]
    if stage < 4:
        rate = v0 if stage == 1 else work[stage - 2]
        for i in range(n):
            xi[i] = c * rate[i]
            v[i] = v0[i] + c * a[i]
        next_rate = work[stage - 1]
        next_rate[:] = v
        next_rate[0], next_rate[1], next_rate[2] = manifold_rk4.rate_entries(xi, v)
    else:
        w = c / 6.0
        for i in range(n):
            xi[i] = w * (v0[i] + 2.0 * work[0, i] + 2.0 * work[1, i] + work[2, i])
            v[i] = v0[i] + w * (work[3, i] + 2.0 * work[4, i] + 2.0 * work[5, i] + work[6, i])
    manifold_rk4.move(q0, xi, x)


@numba.njit(cache=True)
def environment_forces(x, v, tau, point, s, joints, frames, links, link_joint, constants, atmosphere, wrenches, facets):
    """tau plus the orbital environment's generalized forces at (x, v), the reference point s
    seconds after it was at ``point`` (R, V: ``link_forces.propagate_reference``), the terms and
    constants from ``constants`` (``pinocchio_inputs``): ``link_forces.tree_generalized_forces``,
    which fills ``wrenches`` (force, torque per link)."""
    R, V = link_forces.propagate_reference(point[0:3], point[3:6], s, constants[0])
    return link_forces.tree_generalized_forces(
        x,
        v,
        tau,
        joints,
        frames,
        links,
        link_joint,
        R,
        V,
        constants[0],
        constants[3] != 0.0,
        constants[4] != 0.0,
        constants[5] != 0.0,
        atmosphere,
        constants[1],
        constants[2],
        wrenches[0],
        wrenches[1],
        constants[6] != 0.0,
        constants[LIGHT:THIRD],
        facets,
        constants[THIRD:CONSTANTS],
    )


@numba.njit(cache=True)
def pinocchio_inputs(
    stage,
    c,
    a,
    q0,
    v0,
    work,
    x,
    v,
    tau,
    environment,
    point,
    s,
    joints,
    frames,
    links,
    link_joint,
    constants,
    atmosphere,
    wrenches,
    pin_index,
    rotation,
    buffer,
    facets,
):
    """One evaluation's inputs in one call (a call's cost grows with its arguments and every call
    costs ~1 us: the RK4's stage arithmetic is here too): the state (``stage`` > 0: x, v formed by
    ``form_stage``; 0: x, v as they are), the generalized forces (tau, plus with ``environment``
    the orbital environment with the reference point s seconds after it was at ``point`` (R, V:
    ``link_forces.propagate_reference``, here): ``link_forces.tree_generalized_forces``;
    ``constants``: mu, the Earth's rate and radius, the terms on (tidal, gravity gradient,
    drag, SRP), the Sun (``link_forces``' ``light``) and the third bodies' GMs; ``facets``: the links' SRP facets; it
    fills ``wrenches``: force, torque per link), and Pinocchio's q, v, tau, one after
    the other in ``buffer`` (``to_pinocchio``; ``pin_index`` (3, n): idx_q, nq, idx_v of each
    joint coordinate)."""
    if stage:
        form_stage(stage, c, a, q0, v0, work, x, v)
    if environment:
        Q = environment_forces(
            x, v, tau, point, s, joints, frames, links, link_joint, constants, atmosphere, wrenches, facets
        )
    else:
        Q = tau
    nq, nv = buffer.shape[0] - 2 * v.shape[0], v.shape[0]
    to_pinocchio(
        x,
        v,
        Q,
        pin_index[0],
        pin_index[1],
        pin_index[2],
        rotation,
        buffer[:nq],
        buffer[nq : nq + nv],
        buffer[nq + nv :],
    )


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
def unpool(ints, values, nv):
    """The body's arrays from its two pools (``PinocchioBody.pool``): joints, link_joint,
    pin_index, frames, links, constants, atmosphere, wrenches, rotation, buffer, work (10, nv: the
    rates and accelerations of ``form_stage``, xi, then the step's q0 and v0), the step's values
    (environment, h, s, the reference point), tau, the summary (``body_summary``) and the SRP facets."""
    nj, nl, m, b, nq = ints[0], ints[1], ints[2], ints[3], ints[4]
    joints = ints[5 : 5 + 3 * nj].reshape((nj, 3))
    o = 5 + 3 * nj
    link_joint = ints[o : o + nl]
    pin_index = ints[o + nl : o + nl + 3 * m].reshape((3, m))
    frames = values[: 15 * nj].reshape((nj, 15))
    o = 15 * nj
    links = values[o : o + LINK_COLUMNS * nl].reshape((nl, LINK_COLUMNS))
    o += LINK_COLUMNS * nl
    constants = values[o : o + CONSTANTS]
    atmosphere = values[o + CONSTANTS : o + CONSTANTS + 3 * b].reshape((3, b))
    o += CONSTANTS + 3 * b
    wrenches = values[o : o + 6 * nl].reshape((2, nl, 3))
    o += 6 * nl
    rotation = values[o : o + 9].reshape((3, 3))
    buffer = values[o + 9 : o + 9 + nq + 2 * nv]
    o += 9 + nq + 2 * nv
    work = values[o : o + 10 * nv].reshape((10, nv))
    o += 10 * nv
    step = values[o : o + 9]
    tau = values[o + 9 : o + 9 + nv]
    summary = values[o + 9 + nv : o + 34 + nv]
    facets = values[o + 34 + nv :].reshape((-1, 9))
    return (
        joints,
        link_joint,
        pin_index,
        frames,
        links,
        constants,
        atmosphere,
        wrenches,
        rotation,
        buffer,
        work,
        step,
        tau,
        summary,
        facets,
    )


@numba.njit(cache=True)
def summary(ints, values, x, v):
    """``body_summary`` at (x, v) into the pool's summary (``PinocchioBody.pool``)."""
    joints, link_joint, _, frames, links, _, _, _, _, _, _, _, _, summary, _ = unpool(ints, values, v.shape[0])
    body_summary(x, v, joints, frames, links, link_joint, summary)


@numba.njit(cache=True)
def body_summary(x, v, joints, frames, links, link_joint, out):
    """The body's outputs at (x, v) into ``out`` (25): base position, quaternion (w >= 0), twist
    (v, omega), then ``tree_centroidal``'s CoM, its velocity, momentum."""
    out[0], out[1], out[2] = x[3], x[4], x[5]
    qx, qy, qz, qw = quaternion_entries(x[0], x[1], x[2])
    if qw < 0.0:
        qx, qy, qz, qw = -qx, -qy, -qz, -qw
    out[3], out[4], out[5], out[6] = qx, qy, qz, qw
    out[7], out[8], out[9], out[10], out[11], out[12] = v[3], v[4], v[5], v[0], v[1], v[2]
    tree_centroidal(x, v, joints, frames, links, link_joint, out[13:25])


@numba.njit(cache=True)
def tree_centroidal(x, v, joints, frames, links, link_joint, out):
    """The body's CoM, its velocity and the momentum (linear, angular about the CoM), W, at (x, v)
    into ``out`` (12): forward kinematics over the tree (``link_forces.tree_kinematics``), then per
    link with mass m, CoM c, inertia I (about c, W axes) and angular velocity w: p = sum m v_c,
    L = sum (I w + m (c - com) x v_c)."""
    nj, nl = joints.shape[0], link_joint.shape[0]
    block = np.zeros(21 * nj + 12 * nl + 24)
    per_joint = block[: 12 * nj].reshape((4, nj, 3))
    rotation = block[12 * nj : 21 * nj].reshape((nj, 3, 3))
    link_values = block[21 * nj : 21 * nj + 12 * nl].reshape((nl, 4, 3))  # per link: c, v_c, I w, R^T w
    link_forces.tree_kinematics(
        x,
        v,
        joints,
        frames,
        True,
        rotation,
        per_joint[0],
        per_joint[1],
        per_joint[2],
        per_joint[3],
        block[21 * nj + 12 * nl : 21 * nj + 12 * nl + 24],
    )
    out[:] = 0.0
    mass = 0.0
    for n in range(nl):
        j = link_joint[n]
        Rj, link, c, v_c, Iw = rotation[j], links[n], link_values[n, 0], link_values[n, 1], link_values[n, 2]
        w = per_joint[2, j]
        m = link[12]
        mass += m
        for i in range(3):
            c[i] = Rj[i, 0] * link[0] + Rj[i, 1] * link[1] + Rj[i, 2] * link[2]  # CoM from the joint's origin
        v_c[0] = per_joint[3, j, 0] + w[1] * c[2] - w[2] * c[1]
        v_c[1] = per_joint[3, j, 1] + w[2] * c[0] - w[0] * c[2]
        v_c[2] = per_joint[3, j, 2] + w[0] * c[1] - w[1] * c[0]
        for i in range(3):
            c[i] += per_joint[0, j, i]
            out[i] += m * c[i]
            out[6 + i] += m * v_c[i]
        local = link_values[n, 3]  # I w = Rj I_local Rj^T w
        for i in range(3):
            local[i] = Rj[0, i] * w[0] + Rj[1, i] * w[1] + Rj[2, i] * w[2]
        t0 = link[3] * local[0] + link[4] * local[1] + link[5] * local[2]
        t1 = link[6] * local[0] + link[7] * local[1] + link[8] * local[2]
        t2 = link[9] * local[0] + link[10] * local[1] + link[11] * local[2]
        for i in range(3):
            Iw[i] = Rj[i, 0] * t0 + Rj[i, 1] * t1 + Rj[i, 2] * t2
    for i in range(3):
        out[i] /= mass
        out[3 + i] = out[6 + i] / mass
    for n in range(nl):
        c, v_c, Iw = link_values[n, 0], link_values[n, 1], link_values[n, 2]
        m = links[n, 12]
        d0, d1, d2 = c[0] - out[0], c[1] - out[1], c[2] - out[2]
        out[9] += Iw[0] + m * (d1 * v_c[2] - d2 * v_c[1])
        out[10] += Iw[1] + m * (d2 * v_c[0] - d0 * v_c[2])
        out[11] += Iw[2] + m * (d0 * v_c[1] - d1 * v_c[0])


@numba.njit(cache=True)
def rk4_begin(ints, values, x, v, environment, point, h, s):
    """Evaluation 0 of an RK4 step of h seconds from s seconds after the orbit inputs, at (x, v),
    with the environment at ``point`` (``pinocchio_inputs``); keeps the step's start and values
    for ``rk4_evaluation``. The body's arrays in two pools (``PinocchioBody.pool``): a call's
    cost grows with its arguments."""
    (
        joints,
        link_joint,
        pin_index,
        frames,
        links,
        constants,
        atmosphere,
        wrenches,
        rotation,
        buffer,
        work,
        step,
        tau,
        _,
        facets,
    ) = unpool(ints, values, v.shape[0])
    work[8] = x
    work[9] = v
    step[0], step[1], step[2] = 1.0 if environment else 0.0, h, s
    if environment:
        step[3:9] = point
    pinocchio_inputs(
        0,
        0.0,
        v,
        x,
        v,
        work,
        x,
        v,
        tau,
        environment,
        point,
        s,
        joints,
        frames,
        links,
        link_joint,
        constants,
        atmosphere,
        wrenches,
        pin_index,
        rotation,
        buffer,
        facets,
    )


@numba.njit(cache=True)
def rk4_evaluation(ints, values, stage, ddq, x, v):
    """Evaluation ``stage`` (1 to 3) of the RK4 step ``rk4_begin`` began, or with ``stage`` 4 its
    end, into (x, v): the last evaluation's accelerations from Pinocchio's ``ddq``
    (``from_pinocchio``, at the q, v, rotation still in ``buffer``), then ``pinocchio_inputs`` at
    the stage (the environment at its time; none at the end, which is only formed, with the
    body's outputs there: ``body_summary``). With
    ``rk4_begin``, one call per evaluation and no other (``PinocchioBody.rk4_step``)."""
    nv = v.shape[0]
    (
        joints,
        link_joint,
        pin_index,
        frames,
        links,
        constants,
        atmosphere,
        wrenches,
        rotation,
        buffer,
        work,
        step,
        tau,
        summary,
        facets,
    ) = unpool(ints, values, nv)
    nq = ints[4]
    h, s = step[1], step[2]
    a = from_pinocchio(ddq, buffer[nq : nq + nv], rotation, pin_index[2], work[2 + stage])
    c = 0.5 * h if stage < 3 else h
    pinocchio_inputs(
        stage,
        c,
        a,
        work[8],
        work[9],
        work,
        x,
        v,
        tau,
        step[0] != 0.0 and stage < 4,
        step[3:9],
        s + c,
        joints,
        frames,
        links,
        link_joint,
        constants,
        atmosphere,
        wrenches,
        pin_index,
        rotation,
        buffer,
        facets,
    )
    if stage == 4:  # the outputs at the end, in the same call
        body_summary(x, v, joints, frames, links, link_joint, summary)


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


RIGID = 22  # a rigid body for rigid_acceleration: mass, CoM (3), inertia about the CoM (9), its inverse (9)


def rigid_inertia(mass: float, com: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """``rigid_acceleration``'s body (RIGID,): ``mass`` (kg), the CoM ``com`` (m, base frame) and the
    ``inertia`` (3, 3) about it (kg m^2, base axes)."""
    inertia = np.asarray(inertia, dtype=float)
    return np.concatenate([[mass], com, inertia.ravel(), np.linalg.inv(inertia).ravel()])


@numba.njit(cache=True)
def rigid_acceleration(rigid, x, v, Q, a):
    """The forward dynamics of a rigid body (``rigid_inertia``) in the world's coordinates, into
    ``a``: at x (base rotation vector, origin), v (omega, the origin's velocity, W) under Q (torque
    about the base origin, force; W). With c the CoM from the origin and I the inertia about it
    (W axes: R c_b, R I_b R^T): Euler about the CoM, I alpha + omega x I omega = N - c x F, and
    Newton, m (a_o + alpha x c + omega x (omega x c)) = F. Pinocchio's ABA solves the same
    equations (to ~1e-13: ``PinocchioBody.rk4_step``)."""
    m = rigid[0]
    r = manifold_rk4.exp_entries(x[0], x[1], x[2])
    w0, w1, w2 = v[0], v[1], v[2]
    b0 = r[0] * rigid[1] + r[1] * rigid[2] + r[2] * rigid[3]  # c = R c_b
    b1 = r[3] * rigid[1] + r[4] * rigid[2] + r[5] * rigid[3]
    b2 = r[6] * rigid[1] + r[7] * rigid[2] + r[8] * rigid[3]
    o0 = r[0] * w0 + r[3] * w1 + r[6] * w2  # omega in base axes
    o1 = r[1] * w0 + r[4] * w1 + r[7] * w2
    o2 = r[2] * w0 + r[5] * w1 + r[8] * w2
    i0 = rigid[4] * o0 + rigid[5] * o1 + rigid[6] * o2  # I_b omega_b
    i1 = rigid[7] * o0 + rigid[8] * o1 + rigid[9] * o2
    i2 = rigid[10] * o0 + rigid[11] * o1 + rigid[12] * o2
    h0 = r[0] * i0 + r[1] * i1 + r[2] * i2  # I omega, W
    h1 = r[3] * i0 + r[4] * i1 + r[5] * i2
    h2 = r[6] * i0 + r[7] * i1 + r[8] * i2
    F0, F1, F2 = Q[3], Q[4], Q[5]
    n0 = Q[0] - (b1 * F2 - b2 * F1) - (w1 * h2 - w2 * h1)  # N - c x F - omega x I omega
    n1 = Q[1] - (b2 * F0 - b0 * F2) - (w2 * h0 - w0 * h2)
    n2 = Q[2] - (b0 * F1 - b1 * F0) - (w0 * h1 - w1 * h0)
    o0 = r[0] * n0 + r[3] * n1 + r[6] * n2  # ... in base axes, through I_b^-1, back to W: alpha
    o1 = r[1] * n0 + r[4] * n1 + r[7] * n2
    o2 = r[2] * n0 + r[5] * n1 + r[8] * n2
    i0 = rigid[13] * o0 + rigid[14] * o1 + rigid[15] * o2
    i1 = rigid[16] * o0 + rigid[17] * o1 + rigid[18] * o2
    i2 = rigid[19] * o0 + rigid[20] * o1 + rigid[21] * o2
    al0 = r[0] * i0 + r[1] * i1 + r[2] * i2
    al1 = r[3] * i0 + r[4] * i1 + r[5] * i2
    al2 = r[6] * i0 + r[7] * i1 + r[8] * i2
    u0, u1, u2 = w1 * b2 - w2 * b1, w2 * b0 - w0 * b2, w0 * b1 - w1 * b0  # omega x c
    a[0], a[1], a[2] = al0, al1, al2
    a[3] = F0 / m - (al1 * b2 - al2 * b1) - (w1 * u2 - w2 * u1)
    a[4] = F1 / m - (al2 * b0 - al0 * b2) - (w2 * u0 - w0 * u2)
    a[5] = F2 / m - (al0 * b1 - al1 * b0) - (w0 * u1 - w1 * u0)


@numba.njit(cache=True)
def rk4_rigid(ints, values, rigid, x, v, environment, point, h, s, stage_x, stage_v, x_end, v_end):
    """A rigid body's whole RK4 step of h seconds from s seconds after the orbit inputs, at (x, v),
    in one call: each evaluation ``rigid_acceleration`` under tau and (``environment``) the
    environment at ``point`` (``link_forces.tree_generalized_forces``), the stages by
    ``form_stage`` into (stage_x, stage_v), the end into (x_end, v_end) and the body's outputs
    there (``body_summary``), Pinocchio's inputs as ``rk4_evaluation`` leaves them. The body's
    arrays from its pools (``unpool``)."""
    arrays = unpool(ints, values, 6)
    joints, link_joint, pin_index, frames, links, constants, atmosphere, wrenches, rotation, buffer, work = arrays[:11]
    tau, summary, facets = arrays[12:]
    q0, v0 = work[8], work[9]
    q0[:] = x
    v0[:] = v
    xs, vs = q0, v0
    for stage in range(4):  # evaluations at s, s + h/2 (twice), s + h
        Q = tau
        if environment:
            t = s + (0.0, 0.5 * h, 0.5 * h, h)[stage]
            Q = environment_forces(
                xs, vs, tau, point, t, joints, frames, links, link_joint, constants, atmosphere, wrenches, facets
            )
        a = work[3 + stage]
        rigid_acceleration(rigid, xs, vs, Q, a)
        if stage < 3:
            form_stage(stage + 1, 0.5 * h if stage < 2 else h, a, q0, v0, work, stage_x, stage_v)
            xs, vs = stage_x, stage_v
    form_stage(4, h, work[6], q0, v0, work, x_end, v_end)
    body_summary(x_end, v_end, joints, frames, links, link_joint, summary)
    nq = ints[4]  # Pinocchio's inputs and R_W_base at the end, as rk4_evaluation leaves them
    to_pinocchio(
        x_end,
        v_end,
        tau,
        pin_index[0],
        pin_index[1],
        pin_index[2],
        rotation,
        buffer[:nq],
        buffer[nq : nq + 6],
        buffer[nq + 6 :],
    )
