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
the links' inertia from the URDF). The compiled kernels are in
:mod:`components.dynamics.pinocchio_kernels`: an evaluation is one compiled call and one ABA, and
the step's last call also forms the outputs (pose, twist, CoM and momentum over the same tree:
``body_summary``, which agrees with Pinocchio's centroidal momentum to rounding). A rigid body (no
joints) steps in one compiled call without Pinocchio (``rk4_rigid``: a rigid body's Newton-Euler in
place of the ABA: one call instead of five and four ABAs).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from components.constants import EARTH_RATE, R_EARTH
from components.dynamics import link_forces, manifold_rk4
from components.dynamics import pinocchio_kernels as kernels
from components.dynamics.bodies import Body, BodySpec, Environment, ModelError
from components.robots.urdf import UrdfModel

NO_STAGE = np.zeros(0)  # pinocchio_inputs' a when x, v are formed (and its R, V without environment)


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
                if joint.nq == 2:  # continuous: (cos, sin)
                    reference[joint.idx_q : joint.idx_q + 2] = math.cos(value), math.sin(value)
                else:
                    reference[joint.idx_q] = value
            pm = pin.buildReducedModel(full, [full.getJointId(n) for n in self.locked], reference)
        else:
            pm = full
        pm.gravity = pin.Motion.Zero()
        self.pm, self.data = pm, pm.createData()
        joints = [pm.joints[pm.getJointId(j)] for j in self.free_joints]
        self.idx_q = np.array([j.idx_q for j in joints], dtype=np.int64)
        self.nq = np.array([j.nq for j in joints], dtype=np.int64)
        self.idx_v = np.array([j.idx_v for j in joints], dtype=np.int64)
        # the tree for the environment (link_forces.tree_kinematics): joint 1 is the free flyer
        nj = pm.njoints
        self.tree_joints = np.zeros((nj, 3), dtype=np.int64)  # parent, kind, coordinate
        self.tree_frames = np.zeros((nj, 15))  # placement R, p; axis
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
        joint_of, rows, placements = [], [], []
        for i in self.massive_links:
            link = model.links[i]
            frame = pm.frames[self.frame_id[link.name]]
            P = frame.placement
            joint_of.append(frame.parentJoint)
            placements.append(P)
            inertia = P.rotation @ np.array(link.inertia).reshape(3, 3) @ P.rotation.T
            rows.append(
                np.concatenate(
                    [
                        P.rotation @ np.array(link.com) + P.translation,
                        inertia.ravel(),
                        [link.mass, self.drag_k[link.name]],
                    ]
                )
            )
        self.link_joint = np.array(joint_of, dtype=np.int64)
        rows = np.array(rows).reshape(-1, 14)
        srp_links, self.facets = self.srp_tables(
            [model.links[i].name for i in self.massive_links],
            [P.rotation for P in placements],
            [P.translation - row[:3] for P, row in zip(placements, rows)],
        )
        self.tree_links = np.hstack([rows, srp_links])  # CoM, inertia, mass, 1/2 Cd A; Cr A, facet rows (kernels)
        self.total_mass = float(self.tree_links[:, 12].sum())
        self.wrenches = np.zeros((2, len(self.massive_links), 3))  # environment per link, W axes
        self.force, self.torque = self.wrenches
        self.pin_index = np.array([self.idx_q, self.nq, self.idx_v], dtype=np.int64).reshape(3, -1)
        e = environment
        self.terms = np.array([e.tidal, e.gravity_gradient, e.drag and self.has_drag, self.has_srp])
        self.constants = np.array([e.mu, EARTH_RATE, R_EARTH, *self.terms, *e.light(), *e.third()])
        self.no_third = np.zeros(2)
        self.atmosphere = np.array([e.atmosphere.h0, e.atmosphere.rho0, e.atmosphere.scale])
        self.x, self.v = np.zeros(self.ndofs), np.zeros(self.ndofs)
        # the RK4 step: its start (q0, v0), the stage not formed yet (stage, c, a: pinocchio_inputs
        # forms it at the next evaluation; 0: none), the rates and accelerations (form_stage)
        self.q0, self.v0 = self.x, self.v
        self.stage, self.stage_c, self.stage_a = 0, 0.0, NO_STAGE
        self.work = np.zeros((10, self.ndofs))
        self.stage_x, self.stage_v = np.zeros(self.ndofs), np.zeros(self.ndofs)  # (rk4_step's stages)
        self.rotation = np.eye(3)
        self.buffer = np.concatenate([pin.neutral(pm), np.zeros(2 * pm.nv)])
        self.q_pin, self.v_pin, self.tau_pin = np.split(self.buffer, [pm.nq, pm.nq + pm.nv])  # views
        self.step_values = np.zeros(9)  # (rk4_begin's: environment, h, s, point)
        self.summary = np.zeros(25)  # (kernels.body_summary's: pose, twist, CoM, momentum)
        self.pool()
        inertia = pm.inertias[1]  # a rigid body (no joints: Pinocchio merged its links here) steps in one call
        self.rigid = kernels.rigid_inertia(inertia.mass, inertia.lever, inertia.inertia) if pm.nv == 6 else None
        self.begin = functools.partial(kernels.rk4_begin, self.ints, self.values)
        self.evaluate = functools.partial(kernels.rk4_evaluation, self.ints, self.values)
        self.synced = False  # q_pin, v_pin, rotation hold x, v
        self.summarized = False  # summary holds the outputs there
        self.jacobians = False  # data holds the joints' Jacobians there

    def pool(self) -> None:
        """The fixed arrays made views of two (``rk4_evaluation`` takes those: a call's cost grows
        with its arguments): ints (nj, links, joints, atmosphere bands, nq; tree_joints, link_joint,
        pin_index) and values (the model's tree_frames, tree_links, constants, atmosphere; then
        wrenches, rotation, buffer, work, step_values, tau, summary); see ``unpool``."""
        header = [
            len(self.tree_joints),
            len(self.link_joint),
            self.pin_index.shape[1],
            self.atmosphere.shape[1],
            len(self.q_pin),
        ]
        for pool, names in (
            ("ints", ("tree_joints", "link_joint", "pin_index")),
            (
                "values",
                (
                    "tree_frames",
                    "tree_links",
                    "constants",
                    "atmosphere",
                    "wrenches",
                    "rotation",
                    "buffer",
                    "work",
                    "step_values",
                    "tau",
                    "summary",
                    "facets",
                ),
            ),
        ):
            arrays = [getattr(self, name) for name in names]
            start = [np.array(header, dtype=np.int64)] if pool == "ints" else []
            values = np.concatenate(start + [a.ravel() for a in arrays])
            setattr(self, pool, values)
            offset = len(header) if pool == "ints" else 0
            for name, a in zip(names, arrays):
                setattr(self, name, values[offset : offset + a.size].reshape(a.shape))
                offset += a.size
        self.force, self.torque = self.wrenches
        self.light = self.constants[kernels.LIGHT : kernels.THIRD]  # the Sun and Moon: set_sun
        self.third = self.constants[kernels.THIRD :]  # the third bodies' GMs (0: off)
        self.q_pin, self.v_pin, self.tau_pin = np.split(self.buffer, [self.pm.nq, self.pm.nq + self.pm.nv])  # views

    def atmosphere_changed(self) -> None:
        """The kernels read the bands from the pooled copy: refresh it."""
        a = self.environment.atmosphere
        self.atmosphere[0], self.atmosphere[1], self.atmosphere[2] = a.h0, a.rho0, a.scale

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
        self.x, self.v = np.empty(self.ndofs), np.empty(self.ndofs)  # (an x, v is never written once formed)
        self.stage, self.stage_c, self.stage_a, self.synced = stage, c, a, False

    def finish_step(self, h: float, a: np.ndarray) -> None:
        self.next_stage(4, h, a)

    def rk4_step(self, h: float, reference) -> None:
        """The whole RK4 step in five compiled calls and Pinocchio's four ABAs (``rk4_evaluation``);
        the stages' states in scratch arrays, the end's in new ones (as ``next_stage``). A rigid
        body (``rigid``, not None) in one call without Pinocchio (``kernels.rk4_rigid``: the same
        dynamics to ~1e-13; ``rigid = None`` steps it through Pinocchio's ABA, the reference)."""
        if self.stage:
            self._sync()
        point, s = (NO_STAGE, 0.0) if reference is None else reference
        if self.rigid is not None:
            x, v = np.empty(self.ndofs), np.empty(self.ndofs)
            kernels.rk4_rigid(
                self.ints,
                self.values,
                self.rigid,
                self.x,
                self.v,
                reference is not None,
                point,
                h,
                float(s),
                self.stage_x,
                self.stage_v,
                x,
                v,
            )
            self.x, self.v = x, v
            self.stage, self.synced, self.summarized, self.jacobians = 0, True, True, False
            return
        self.begin(self.x, self.v, reference is not None, point, h, float(s))
        evaluate, x, v = self.evaluate, self.stage_x, self.stage_v
        aba, pm, data, q_pin, v_pin, tau_pin = self.pin.aba, self.pm, self.data, self.q_pin, self.v_pin, self.tau_pin
        evaluate(1, aba(pm, data, q_pin, v_pin, tau_pin), x, v)
        evaluate(2, aba(pm, data, q_pin, v_pin, tau_pin), x, v)
        evaluate(3, aba(pm, data, q_pin, v_pin, tau_pin), x, v)
        self.x, self.v = np.empty(self.ndofs), np.empty(self.ndofs)
        evaluate(4, aba(pm, data, q_pin, v_pin, tau_pin), self.x, self.v)  # (and the summary)
        self.stage, self.synced, self.summarized, self.jacobians = 0, True, True, False

    # -- dynamics
    def _sync(self) -> None:
        """x, v formed, Pinocchio's q, v, tau and R_W_base at them."""
        kernels.pinocchio_inputs(
            self.stage,
            self.stage_c,
            self.stage_a,
            self.q0,
            self.v0,
            self.work,
            self.x,
            self.v,
            self.tau,
            False,
            NO_STAGE,
            0.0,
            self.tree_joints,
            self.tree_frames,
            self.tree_links,
            self.link_joint,
            self.constants,
            self.atmosphere,
            self.wrenches,
            self.pin_index,
            self.rotation,
            self.buffer,
            self.facets,
        )
        self.stage, self.synced, self.summarized, self.jacobians = 0, True, False, False

    def forward_dynamics(self, reference) -> np.ndarray:
        point, s = (NO_STAGE, 0.0) if reference is None else reference  # (_sync inlined: four times a step)
        kernels.pinocchio_inputs(
            self.stage,
            self.stage_c,
            self.stage_a,
            self.q0,
            self.v0,
            self.work,
            self.x,
            self.v,
            self.tau,
            reference is not None,
            point,
            float(s),
            self.tree_joints,
            self.tree_frames,
            self.tree_links,
            self.link_joint,
            self.constants,
            self.atmosphere,
            self.wrenches,
            self.pin_index,
            self.rotation,
            self.buffer,
            self.facets,
        )
        self.stage, self.synced, self.summarized, self.jacobians = 0, True, False, False
        ddq = self.pin.aba(self.pm, self.data, self.q_pin, self.v_pin, self.tau_pin)
        return kernels.from_pinocchio(ddq, self.v_pin, self.rotation, self.idx_v, np.empty(self.ndofs))

    def inverse_mass(self) -> np.ndarray:
        if not self.synced:
            self._sync()
        upper = self.pin.computeMinverse(self.pm, self.data, self.q_pin)
        return kernels.world_inverse_mass(upper, self.rotation, self.idx_v)

    # -- outputs
    def base_pose(self):
        if not self.synced:
            self._sync()
        return self.rotation.copy(), self.x[3:6]  # (an x is never written once formed)

    def orientation(self, R: np.ndarray) -> np.ndarray:
        """The configuration's quaternion (w = cos(|phi|/2), made >= 0)."""
        if not self.synced:
            self._sync()
        q = self.q_pin[3:7].copy()
        return -q if q[3] < 0.0 else q

    def _summary(self) -> np.ndarray:
        if not self.synced:
            self._sync()
        if not self.summarized:
            kernels.summary(self.ints, self.values, self.x, self.v)
            self.summarized = True
        return self.summary

    def state_outputs(self) -> dict[str, np.ndarray]:
        o = self._summary().copy()
        return {
            "position": o[0:3],
            "orientation": o[3:7],
            "twist": o[7:13],
            "q": self.joint_positions(self.x),
            "qd": self.joint_velocities(self.v),
            "com": o[13:16],
            "momentum": o[19:25],
        }

    def com(self) -> np.ndarray:
        return self._summary()[13:16].copy()

    def com_velocity(self) -> np.ndarray:
        return self._summary()[16:19].copy()

    def momentum(self, com=None, base_position=None) -> np.ndarray:
        return self._summary()[19:25].copy()  # (linear, angular about the CoM), W axes

    def _frames(self) -> None:
        if not self.synced:
            self._sync()
        self.pin.framesForwardKinematics(self.pm, self.data, self.q_pin)

    def link_transforms(self) -> np.ndarray:
        self._frames()
        return np.array([self.data.oMf[self.frame_id[link]].homogeneous for link in self.link_names])

    def environment_wrenches(self, R, V):
        return self._wrenches(
            R,
            V,
            (((True, True, False, False, False), ((0, 0), (2, 1))), ((False, False, True, False, False), ((1, 0),))),
            3,
        )

    def srp_wrenches(self, R, V):
        return self._wrenches(R, V, (((False, False, False, True, False), ((0, 0), (1, 1))),), 2)

    def third_body_forces(self, R, V):
        return self._wrenches(R, V, (((False, False, False, False, True), ((0, 0),)),), 1)[0]

    def _wrenches(self, R, V, calls, count):
        """Per URDF link, W axes: ``count`` outputs, each call's terms (tidal, gravity gradient,
        drag, SRP, third bodies) on filling outputs from its (output, force 0 or torque 1) pairs."""
        R, V = np.asarray(R, dtype=float), np.asarray(V, dtype=float)
        if self.stage:
            self._sync()
        out = [np.zeros((len(self.link_names), 3)) for _ in range(count)]
        for terms, parts in calls:
            third = terms[4] and self.third.any()
            terms = self.terms & np.array(terms[:4])
            if terms.any() or third:
                link_forces.tree_generalized_forces(
                    self.x,
                    self.v,
                    self.tau,
                    self.tree_joints,
                    self.tree_frames,
                    self.tree_links,
                    self.link_joint,
                    R,
                    V,
                    self.environment.mu,
                    terms[0],
                    terms[1],
                    terms[2],
                    self.atmosphere,
                    EARTH_RATE,
                    R_EARTH,
                    self.force,
                    self.torque,
                    terms[3],
                    self.light,
                    self.facets,
                    self.third if third else self.no_third,
                )
                for part, wrench in parts:
                    out[part][self.massive_links] = self.wrenches[wrench]
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
        if not self.jacobians:  # the joints' Jacobians, once per state
            pin.computeJointJacobians(self.pm, self.data, self.q_pin)
            self.jacobians = True
        frame = self.frame_id[link]
        J = pin.getFrameJacobian(self.pm, self.data, frame, pin.LOCAL_WORLD_ALIGNED)  # [linear; angular]
        r = pin.updateFramePlacement(self.pm, self.data, frame).rotation @ point
        return kernels.world_point_jacobian(J, r, self.rotation, self.idx_v)

    def point_bias(self, link: str, point: np.ndarray) -> np.ndarray:
        """Pinocchio's forward kinematics at the acceleration that is zero in the world's
        coordinates (``zero_world_acceleration``)."""
        pin = self.pin
        if not self.synced:
            self._sync()
        a = kernels.zero_world_acceleration(self.v_pin)
        pin.forwardKinematics(self.pm, self.data, self.q_pin, self.v_pin, a)  # (the same q: data.J holds)
        frame = self.frame_id[link]
        r = pin.updateFramePlacement(self.pm, self.data, frame).rotation @ point
        acceleration = pin.getFrameClassicalAcceleration(self.pm, self.data, frame, pin.LOCAL_WORLD_ALIGNED)
        w = pin.getFrameVelocity(self.pm, self.data, frame, pin.LOCAL_WORLD_ALIGNED).angular
        return kernels.point_acceleration(acceleration.linear, acceleration.angular, w, r)
