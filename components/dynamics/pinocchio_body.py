"""A body's dynamics by Pinocchio: ABA on a free-flyer model, converted to the world's coordinates.

Pinocchio's free flyer has the configuration (base origin, quaternion [x, y, z, w]) and the
velocity (v_b, omega_b) in the BASE frame; the world's coordinates (components/dynamics/bodies.py)
are DART's chart: base rotation vector and origin, velocities (omega, v) in W axes. With
R = R_W_base, at this body's boundary:

    v_pin = (R^T v, R^T omega, joint rates),   tau_pin = (R^T f, R^T t, joint forces),
    dv/dt = R (dv_b/dt + omega_b x v_b),       domega/dt = R domega_b/dt,

(the first a classical acceleration from the spatial one) and M^-1 = T^T M_pin^-1 T with T the
orthogonal map v -> v_pin. Continuous joints are (cos q, sin q) in Pinocchio's configuration.

The model is the URDF text the DART loader gets (``UrdfModel.text``: meshes resolved), with the
locked joints welded at their positions (``pinocchio.buildReducedModel``); mimic joints are
independent joints (the world holds them). The environment goes in as generalized forces
(``link_forces.tree_generalized_forces``: forward kinematics over the model's tree, compiled,
the links' inertia from the URDF): one compiled call, ABA, one compiled call per evaluation.
"""
from __future__ import annotations

import functools
import math

import numba
import numpy as np

from components.constants import EARTH_RATE, R_EARTH
from components.dynamics import link_forces, manifold_rk4
from components.dynamics.bodies import Body, BodySpec, Environment, ModelError
from components.robots.urdf import UrdfModel

NO_STAGE = np.zeros(0)     # pinocchio_inputs' a when x, v are formed (and its R, V without environment)


@numba.njit(cache=True)
def to_pinocchio(x, v, Q, idx_q, nq, idx_v, rotation, q_pin, v_pin, tau_pin):
    """Pinocchio's configuration, velocity and generalized forces from the world's coordinates
    (written into q_pin, v_pin, tau_pin), and R_W_base into ``rotation``."""
    m = manifold_rk4.exp_entries(x[0], x[1], x[2])
    for i in range(3):
        rotation[i, 0], rotation[i, 1], rotation[i, 2] = m[3 * i], m[3 * i + 1], m[3 * i + 2]
    R = rotation
    px, py, pz = x[0], x[1], x[2]
    t = math.sqrt(px * px + py * py + pz * pz)
    s = 0.5 - t * t / 48.0 if t < 1e-6 else math.sin(0.5 * t) / t     # sin(t/2) / t
    q_pin[0], q_pin[1], q_pin[2] = x[3], x[4], x[5]
    q_pin[3], q_pin[4], q_pin[5], q_pin[6] = s * px, s * py, s * pz, math.cos(0.5 * t)
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
def pinocchio_inputs(stage, c, a, q0, v0, work, x, v, tau, environment, point, s, joints, frames, links, link_joint,
                     constants, atmosphere, wrenches, pin_index, rotation, buffer):
    """One evaluation's inputs in one call (a call's cost grows with its arguments and every call
    costs ~1 us: the RK4's stage arithmetic is here too): the state (``stage`` > 0: x, v formed by
    ``form_stage``; 0: x, v as they are), the generalized forces (tau, plus with ``environment``
    the orbital environment with the reference point s seconds after it was at ``point`` (R, V:
    ``link_forces.propagate_reference``, here): ``link_forces.tree_generalized_forces``;
    ``constants``: mu, the Earth's rate and radius, and the terms on (tidal, gravity gradient,
    drag); it fills ``wrenches``: force, torque per link), and Pinocchio's q, v, tau, one after
    the other in ``buffer`` (``to_pinocchio``; ``pin_index`` (3, n): idx_q, nq, idx_v of each
    joint coordinate)."""
    if stage:
        form_stage(stage, c, a, q0, v0, work, x, v)
    if environment:
        R, V = link_forces.propagate_reference(point[0:3], point[3:6], s, constants[0])
        Q = link_forces.tree_generalized_forces(x, v, tau, joints, frames, links, link_joint, R, V, constants[0],
                                                constants[3] != 0.0, constants[4] != 0.0, constants[5] != 0.0,
                                                atmosphere, constants[1], constants[2], wrenches[0], wrenches[1])
    else:
        Q = tau
    nq, nv = buffer.shape[0] - 2 * v.shape[0], v.shape[0]
    to_pinocchio(x, v, Q, pin_index[0], pin_index[1], pin_index[2], rotation, buffer[:nq], buffer[nq:nq + nv],
                 buffer[nq + nv:])


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
def unpool(ints, model, scratch, nv):
    """The body's arrays from its three pools (``PinocchioBody.pool``): joints, link_joint,
    pin_index, frames, links, constants, atmosphere, wrenches, rotation, buffer, work (10, nv: the
    rates and accelerations of ``form_stage``, xi, then the step's q0 and v0) and the step's
    values (environment, h, s, the reference point)."""
    nj, nl, m, b, nq = ints[0], ints[1], ints[2], ints[3], ints[4]
    joints = ints[5:5 + 3 * nj].reshape((nj, 3))
    o = 5 + 3 * nj
    link_joint = ints[o:o + nl]
    pin_index = ints[o + nl:o + nl + 3 * m].reshape((3, m))
    frames = model[:15 * nj].reshape((nj, 15))
    o = 15 * nj
    links = model[o:o + 14 * nl].reshape((nl, 14))
    o += 14 * nl
    constants = model[o:o + 6]
    atmosphere = model[o + 6:o + 6 + 3 * b].reshape((3, b))
    wrenches = scratch[:6 * nl].reshape((2, nl, 3))
    o = 6 * nl
    rotation = scratch[o:o + 9].reshape((3, 3))
    buffer = scratch[o + 9:o + 9 + nq + 2 * nv]
    o += 9 + nq + 2 * nv
    work = scratch[o:o + 10 * nv].reshape((10, nv))
    step = scratch[o + 10 * nv:o + 10 * nv + 9]
    return joints, link_joint, pin_index, frames, links, constants, atmosphere, wrenches, rotation, buffer, work, step


@numba.njit(cache=True)
def rk4_begin(ints, model, scratch, tau, x, v, environment, point, h, s):
    """Evaluation 0 of an RK4 step of h seconds from s seconds after the orbit inputs, at (x, v),
    with the environment at ``point`` (``pinocchio_inputs``); keeps the step's start and values
    for ``rk4_evaluation``. The body's arrays in three pools (``PinocchioBody.pool``): a call's
    cost grows with its arguments."""
    joints, link_joint, pin_index, frames, links, constants, atmosphere, wrenches, rotation, buffer, work, step = \
        unpool(ints, model, scratch, v.shape[0])
    work[8] = x
    work[9] = v
    step[0], step[1], step[2] = 1.0 if environment else 0.0, h, s
    if environment:
        step[3:9] = point
    pinocchio_inputs(0, 0.0, v, x, v, work, x, v, tau, environment, point, s, joints, frames, links, link_joint,
                     constants, atmosphere, wrenches, pin_index, rotation, buffer)


@numba.njit(cache=True)
def rk4_evaluation(ints, model, scratch, tau, stage, ddq, x, v):
    """Evaluation ``stage`` (1 to 3) of the RK4 step ``rk4_begin`` began, or with ``stage`` 4 its
    end, into (x, v): the last evaluation's accelerations from Pinocchio's ``ddq``
    (``from_pinocchio``, at the q, v, rotation still in ``buffer``), then ``pinocchio_inputs`` at
    the stage (the environment at its time; none at the end, which is only formed). With
    ``rk4_begin``, one call per evaluation and no other (``PinocchioBody.rk4_step``)."""
    nv = v.shape[0]
    joints, link_joint, pin_index, frames, links, constants, atmosphere, wrenches, rotation, buffer, work, step = \
        unpool(ints, model, scratch, nv)
    nq = ints[4]
    h, s = step[1], step[2]
    a = from_pinocchio(ddq, buffer[nq:nq + nv], rotation, pin_index[2], work[2 + stage])
    c = 0.5 * h if stage < 3 else h
    pinocchio_inputs(stage, c, a, work[8], work[9], work, x, v, tau, step[0] != 0.0 and stage < 4, step[3:9], s + c,
                     joints, frames, links, link_joint, constants, atmosphere, wrenches, pin_index, rotation, buffer)


@numba.njit(cache=True)
def velocity_map(rotation, idx_v, nv):
    """T (nv, n): v_pin = T v, from the world's coordinates to Pinocchio's velocity (orthogonal)."""
    T = np.zeros((nv, 6 + idx_v.shape[0]))
    for i in range(3):
        for k in range(3):
            T[i, 3 + k] = rotation[k, i]                  # v_b = R^T v
            T[3 + i, k] = rotation[k, i]                  # omega_b = R^T omega
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
        point[3, c] = J[0, c] - (r[1] * w2 - r[2] * w1)     # v + omega x r
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


class PinocchioBody(Body):
    """A body as a Pinocchio model; the state is held here, in the world's coordinates (``x``, ``v``)."""
    engine = "pinocchio"

    def __init__(self, spec: BodySpec, model: UrdfModel, environment: Environment):
        import pinocchio as pin

        super().__init__(spec, model, environment)
        self.pin = pin
        try:
            full = pin.buildModelFromXML(model.text, pin.JointModelFreeFlyer())
        except (RuntimeError, ValueError) as e:
            raise ModelError(f"{spec.name}.urdf", f"Pinocchio could not load {spec.urdf}: {e}") from None
        if self.locked:
            reference = pin.neutral(full)
            for name, value in self.locked.items():
                joint = full.joints[full.getJointId(name)]
                if joint.nq == 2:                              # continuous: (cos, sin)
                    reference[joint.idx_q:joint.idx_q + 2] = math.cos(value), math.sin(value)
                else:
                    reference[joint.idx_q] = value
            pm = pin.buildReducedModel(full, [full.getJointId(n) for n in self.locked], reference)
        else:
            pm = full
        pm.gravity = pin.Motion.Zero()
        self.pm, self.data = pm, pm.createData()
        self.data_com = self.data.com                  # (a view of data's vector: its size is the model's)
        joints = [pm.joints[pm.getJointId(j)] for j in self.free_joints]
        self.idx_q = np.array([j.idx_q for j in joints], dtype=np.int64)
        self.nq = np.array([j.nq for j in joints], dtype=np.int64)
        self.idx_v = np.array([j.idx_v for j in joints], dtype=np.int64)
        # the tree for the environment (link_forces.tree_kinematics): joint 1 is the free flyer
        nj = pm.njoints
        self.tree_joints = np.zeros((nj, 3), dtype=np.int64)            # parent, kind, coordinate
        self.tree_frames = np.zeros((nj, 15))                           # placement R, p; axis
        for j in range(1, nj):
            placement = pm.jointPlacements[j]
            self.tree_frames[j, :12] = np.concatenate([placement.rotation.ravel(), placement.translation])
            self.tree_joints[j, 0] = pm.parents[j]
            if j >= 2:
                joint = model.joint(pm.names[j])
                kind = link_forces.PRISMATIC if joint.type == "prismatic" else link_forces.REVOLUTE
                self.tree_joints[j, 1:] = kind, 6 + self.free_joints.index(joint.name)
                self.tree_frames[j, 12:] = joint.axis
        # links: each URDF link's frame (its joint, its placement there); those with mass
        self.frame_id = {link: pm.getFrameId(link, pin.BODY) for link in self.link_names}
        self.massive_links = np.array([i for i, link in enumerate(model.links) if link.mass > 0.0], dtype=np.int64)
        joint_of, rows = [], []
        for i in self.massive_links:
            link = model.links[i]
            frame = pm.frames[self.frame_id[link.name]]
            P = frame.placement
            joint_of.append(frame.parentJoint)
            inertia = P.rotation @ np.array(link.inertia).reshape(3, 3) @ P.rotation.T
            rows.append(np.concatenate([P.rotation @ np.array(link.com) + P.translation, inertia.ravel(),
                                        [link.mass, self.drag_k[link.name]]]))
        self.link_joint = np.array(joint_of, dtype=np.int64)
        self.tree_links = np.array(rows).reshape(-1, 14)                # CoM, inertia, mass, 1/2 Cd A
        self.total_mass = float(self.tree_links[:, 12].sum())
        self.wrenches = np.zeros((2, len(self.massive_links), 3))   # environment per link, W axes
        self.force, self.torque = self.wrenches
        self.pin_index = np.array([self.idx_q, self.nq, self.idx_v], dtype=np.int64).reshape(3, -1)
        e = environment
        self.terms = np.array([e.tidal, e.gravity_gradient, e.drag and self.has_drag])
        self.constants = np.array([e.mu, EARTH_RATE, R_EARTH, *self.terms])
        self.atmosphere = np.array([e.atmosphere.h0, e.atmosphere.rho0, e.atmosphere.scale])
        self.x, self.v = np.zeros(self.ndofs), np.zeros(self.ndofs)
        # the RK4 step: its start (q0, v0), the stage not formed yet (stage, c, a: pinocchio_inputs
        # forms it at the next evaluation; 0: none), the rates and accelerations (form_stage)
        self.q0, self.v0 = self.x, self.v
        self.stage, self.stage_c, self.stage_a = 0, 0.0, NO_STAGE
        self.work = np.zeros((10, self.ndofs))
        self.stage_x, self.stage_v = np.zeros(self.ndofs), np.zeros(self.ndofs)   # (rk4_step's stages)
        self.rotation = np.eye(3)
        self.buffer = np.concatenate([pin.neutral(pm), np.zeros(2 * pm.nv)])
        self.q_pin, self.v_pin, self.tau_pin = np.split(self.buffer, [pm.nq, pm.nq + pm.nv])   # views
        self.step_values = np.zeros(9)                        # (rk4_begin's: environment, h, s, point)
        self.pool()
        self.begin = functools.partial(rk4_begin, self.ints, self.model_values, self.scratch, self.tau)
        self.evaluate = functools.partial(rk4_evaluation, self.ints, self.model_values, self.scratch, self.tau)
        self.synced = False                                    # q_pin, v_pin, rotation hold x, v
        self.centroidal = False                                # data holds the centroidal momentum there
        self.jacobians = False                                 # data holds the joints' Jacobians there

    def pool(self) -> None:
        """The fixed arrays made views of three (``rk4_evaluation`` takes those): ints (nj, links,
        joints, atmosphere bands, nq; tree_joints, link_joint, pin_index), model values
        (tree_frames, tree_links, constants, atmosphere), scratch (wrenches, rotation, buffer, work,
        step_values); see ``unpool``."""
        header = [len(self.tree_joints), len(self.link_joint), self.pin_index.shape[1], self.atmosphere.shape[1],
                  len(self.q_pin)]
        for pool, names in (("ints", ("tree_joints", "link_joint", "pin_index")),
                            ("model_values", ("tree_frames", "tree_links", "constants", "atmosphere")),
                            ("scratch", ("wrenches", "rotation", "buffer", "work", "step_values"))):
            arrays = [getattr(self, name) for name in names]
            start = [np.array(header, dtype=np.int64)] if pool == "ints" else []
            values = np.concatenate(start + [a.ravel() for a in arrays])
            setattr(self, pool, values)
            offset = len(header) if pool == "ints" else 0
            for name, a in zip(names, arrays):
                setattr(self, name, values[offset:offset + a.size].reshape(a.shape))
                offset += a.size
        self.force, self.torque = self.wrenches
        self.q_pin, self.v_pin, self.tau_pin = np.split(self.buffer, [self.pm.nq, self.pm.nq + self.pm.nv])   # views

    # -- state
    def positions(self) -> np.ndarray:
        if self.stage:
            self._sync()
        return self.x

    def velocities(self) -> np.ndarray:
        if self.stage:
            self._sync()
        return self.v

    def set_state(self, positions, velocities) -> None:
        self.x, self.v = np.array(positions, dtype=float), np.array(velocities, dtype=float)
        self.stage, self.synced = 0, False

    def set_stage(self, q0, xi, velocities) -> None:
        self.set_state(manifold_rk4.moved(q0, xi), velocities)

    def set_velocities(self, velocities) -> None:
        if self.stage:
            self._sync()
        self.v = np.array(velocities, dtype=float)
        self.synced = False

    # -- the RK4 step: each stage formed inside the next evaluation's one compiled call
    def begin_step(self) -> None:
        if self.stage:
            self._sync()
        self.q0, self.v0 = self.x, self.v

    def next_stage(self, stage: int, c: float, a: np.ndarray) -> None:
        self.x, self.v = np.empty(self.ndofs), np.empty(self.ndofs)     # (an x, v is never written once formed)
        self.stage, self.stage_c, self.stage_a, self.synced = stage, c, a, False

    def finish_step(self, h: float, a: np.ndarray) -> None:
        self.next_stage(4, h, a)

    def rk4_step(self, h: float, reference) -> None:
        """The whole RK4 step in five compiled calls and Pinocchio's four ABAs (``rk4_evaluation``);
        the stages' states in scratch arrays, the end's in new ones (as ``next_stage``)."""
        if self.stage:
            self._sync()
        point, s = (NO_STAGE, 0.0) if reference is None else reference
        self.begin(self.x, self.v, reference is not None, point, h, float(s))
        evaluate, x, v = self.evaluate, self.stage_x, self.stage_v
        aba, pm, data, q_pin, v_pin, tau_pin = self.pin.aba, self.pm, self.data, self.q_pin, self.v_pin, self.tau_pin
        evaluate(1, aba(pm, data, q_pin, v_pin, tau_pin), x, v)
        evaluate(2, aba(pm, data, q_pin, v_pin, tau_pin), x, v)
        evaluate(3, aba(pm, data, q_pin, v_pin, tau_pin), x, v)
        self.x, self.v = np.empty(self.ndofs), np.empty(self.ndofs)
        evaluate(4, aba(pm, data, q_pin, v_pin, tau_pin), self.x, self.v)
        self.stage, self.synced, self.centroidal, self.jacobians = 0, True, False, False

    # -- dynamics
    def _sync(self) -> None:
        """x, v formed, Pinocchio's q, v, tau and R_W_base at them."""
        pinocchio_inputs(self.stage, self.stage_c, self.stage_a, self.q0, self.v0, self.work, self.x, self.v, self.tau,
                         False, NO_STAGE, 0.0, self.tree_joints, self.tree_frames, self.tree_links, self.link_joint,
                         self.constants, self.atmosphere, self.wrenches, self.pin_index, self.rotation, self.buffer)
        self.stage, self.synced, self.centroidal, self.jacobians = 0, True, False, False

    def forward_dynamics(self, reference) -> np.ndarray:
        point, s = (NO_STAGE, 0.0) if reference is None else reference    # (_sync inlined: four times a step)
        pinocchio_inputs(self.stage, self.stage_c, self.stage_a, self.q0, self.v0, self.work, self.x, self.v, self.tau,
                         reference is not None, point, float(s), self.tree_joints, self.tree_frames, self.tree_links,
                         self.link_joint, self.constants, self.atmosphere, self.wrenches, self.pin_index,
                         self.rotation, self.buffer)
        self.stage, self.synced, self.centroidal, self.jacobians = 0, True, False, False
        ddq = self.pin.aba(self.pm, self.data, self.q_pin, self.v_pin, self.tau_pin)
        return from_pinocchio(ddq, self.v_pin, self.rotation, self.idx_v, np.empty(self.ndofs))

    def inverse_mass(self) -> np.ndarray:
        if not self.synced:
            self._sync()
        return world_inverse_mass(self.pin.computeMinverse(self.pm, self.data, self.q_pin), self.rotation, self.idx_v)

    # -- outputs
    def base_pose(self):
        if not self.synced:
            self._sync()
        return self.rotation.copy(), self.x[3:6]                # (an x is never written once formed)

    def orientation(self, R: np.ndarray) -> np.ndarray:
        """The configuration's quaternion (w = cos(|phi|/2), made >= 0)."""
        if not self.synced:
            self._sync()
        q = self.q_pin[3:7].copy()
        return -q if q[3] < 0.0 else q

    def _centroidal(self):
        if not self.synced:
            self._sync()
        if not self.centroidal:
            self.hg = self.pin.computeCentroidalMomentum(self.pm, self.data, self.q_pin, self.v_pin)
            self.centroidal = True
        return self.data

    def com(self) -> np.ndarray:
        self._centroidal()
        return self.data_com[0].copy()          # (data.com fetched once: each fetch costs a microsecond)

    def com_velocity(self) -> np.ndarray:
        return self._centroidal().vcom[0].copy()

    def momentum(self, com=None, base_position=None) -> np.ndarray:
        self._centroidal()
        return self.hg.vector.copy()             # (linear, angular about the CoM), W axes

    def _frames(self) -> None:
        if not self.synced:
            self._sync()
        self.pin.framesForwardKinematics(self.pm, self.data, self.q_pin)

    def link_transforms(self) -> np.ndarray:
        self._frames()
        return np.array([self.data.oMf[self.frame_id[link]].homogeneous for link in self.link_names])

    def environment_wrenches(self, R, V):
        R, V = np.asarray(R, dtype=float), np.asarray(V, dtype=float)
        if self.stage:
            self._sync()
        out = [np.zeros((len(self.link_names), 3)) for _ in range(3)]
        for terms, parts in (((True, True, False), (0, 2)), ((False, False, True), (1,))):
            terms = self.terms & np.array(terms)
            if terms.any():
                link_forces.tree_generalized_forces(
                    self.x, self.v, self.tau, self.tree_joints, self.tree_frames, self.tree_links, self.link_joint,
                    R, V, self.environment.mu, terms[0], terms[1], terms[2], self.atmosphere, EARTH_RATE, R_EARTH,
                    self.force, self.torque)
                for part in parts:
                    out[part][self.massive_links] = self.force if part < 2 else self.torque
        return tuple(out)

    # -- a grasp
    def link_pose(self, link: str):
        self._frames()
        placement = self.data.oMf[self.frame_id[link]]
        return placement.translation.copy(), placement.rotation.copy()

    def point_jacobian(self, link: str, point: np.ndarray) -> np.ndarray:
        pin = self.pin
        if not self.synced:
            self._sync()
        if not self.jacobians:                                 # the joints' Jacobians, once per state
            pin.computeJointJacobians(self.pm, self.data, self.q_pin)
            self.jacobians = True
        frame = self.frame_id[link]
        J = pin.getFrameJacobian(self.pm, self.data, frame, pin.LOCAL_WORLD_ALIGNED)   # [linear; angular]
        r = pin.updateFramePlacement(self.pm, self.data, frame).rotation @ point
        return world_point_jacobian(J, r, self.rotation, self.idx_v)

    def point_bias(self, link: str, point: np.ndarray) -> np.ndarray:
        """Pinocchio's forward kinematics at the acceleration that is zero in the world's
        coordinates (``zero_world_acceleration``)."""
        pin = self.pin
        if not self.synced:
            self._sync()
        a = zero_world_acceleration(self.v_pin)
        pin.forwardKinematics(self.pm, self.data, self.q_pin, self.v_pin, a)   # (the same q: data.J holds)
        frame = self.frame_id[link]
        r = pin.updateFramePlacement(self.pm, self.data, frame).rotation @ point
        acceleration = pin.getFrameClassicalAcceleration(self.pm, self.data, frame, pin.LOCAL_WORLD_ALIGNED)
        w = pin.getFrameVelocity(self.pm, self.data, frame, pin.LOCAL_WORLD_ALIGNED).angular
        return point_acceleration(acceleration.linear, acceleration.angular, w, r)
