"""The compiled stepping kernels of :mod:`components.dynamics.pinocchio_body`: the RK4 evaluations of a
body that steps itself (``rk4_begin``, ``rk4_evaluation``: one call per evaluation, the stage
arithmetic, the environment and Pinocchio's inputs in it; a call's cost grows with its arguments,
so the body's arrays come in two pools, ``unpool``), and a rigid body's (no joints) whole step in
one call without Pinocchio (``rk4_rigid``); the conversions to and from Pinocchio's coordinates
are in :mod:`components.dynamics.pinocchio_conversions`, the body's outputs in
:mod:`components.dynamics.tree_outputs`. numba, no fastmath: IEEE arithmetic, the same bits at
every run.
"""

from __future__ import annotations

import numba
import numpy as np

from components.dynamics import link_forces, manifold_rk4, tree_forces, tree_outputs
from components.dynamics import pinocchio_conversions as conversions

LINK_COLUMNS = 17  # a link's row: CoM (3), inertia (9), mass, 1/2 Cd A, Cr A, first facet, facets
# mu, Earth's rate, radius, tidal, gravity gradient, drag, SRP; light; the GMs of the third bodies (Sun, Moon; 0: off)
LIGHT = 7
THIRD = LIGHT + link_forces.LIGHT_SIZE
CONSTANTS = THIRD + 2


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
    constants from ``constants`` (``pinocchio_inputs``): ``tree_forces.tree_generalized_forces``,
    which fills ``wrenches`` (force, torque per link)."""
    R, V = link_forces.propagate_reference(point[0:3], point[3:6], s, constants[0])
    return tree_forces.tree_generalized_forces(
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
    ``link_forces.propagate_reference``, here): ``tree_forces.tree_generalized_forces``;
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
    conversions.to_pinocchio(
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
    tree_outputs.body_summary(x, v, joints, frames, links, link_joint, summary)


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
    a = conversions.from_pinocchio(ddq, buffer[nq : nq + nv], rotation, pin_index[2], work[2 + stage])
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
        tree_outputs.body_summary(x, v, joints, frames, links, link_joint, summary)


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
    environment at ``point`` (``tree_forces.tree_generalized_forces``), the stages by
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
    tree_outputs.body_summary(x_end, v_end, joints, frames, links, link_joint, summary)
    nq = ints[4]  # Pinocchio's inputs and R_W_base at the end, as rk4_evaluation leaves them
    conversions.to_pinocchio(
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
