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
(``tree_forces.tree_generalized_forces``: forward kinematics over the model's tree, compiled,
the links' inertia from the URDF). The compiled kernels are in
:mod:`components.dynamics.pinocchio_kernels`: an evaluation is one compiled call and one ABA, and
the step's last call also forms the outputs (pose, twist, CoM and momentum over the same tree:
``tree_outputs.body_summary``, which agrees with Pinocchio's centroidal momentum to rounding). A rigid body (no
joints) steps in one compiled call without Pinocchio (``rk4_rigid``: a rigid body's Newton-Euler in
place of the ABA: one call instead of five and four ABAs). The conversions between the coordinates
are compiled in :mod:`components.dynamics.pinocchio_conversions`; the model and its tables are made
in :mod:`components.dynamics.pinocchio_model`, the outputs given in
:mod:`components.dynamics.pinocchio_outputs`.
"""

from __future__ import annotations

import functools

import numpy as np

from components.constants import EARTH_RATE, R_EARTH
from components.dynamics import manifold_rk4
from components.dynamics import pinocchio_conversions as conversions
from components.dynamics import pinocchio_kernels as kernels
from components.dynamics.bodies import Body, BodySpec, Environment
from components.dynamics.pinocchio_model import link_rows, load_model, tree_tables
from components.dynamics.pinocchio_outputs import PinocchioOutputs
from components.robots.urdf import UrdfModel

NO_STAGE = np.zeros(0)  # pinocchio_inputs' a when x, v are formed (and its R, V without environment)


class PinocchioBody(PinocchioOutputs, Body):
    """A body as a Pinocchio model; the state is held here, in the world's coordinates (``x``, ``v``)."""

    engine = "pinocchio"

    def __init__(self, spec: BodySpec, model: UrdfModel, environment: Environment):
        import pinocchio as pin

        super().__init__(spec, model, environment)
        self.pin = pin
        pm = load_model(pin, spec, model, self.locked)
        self.pm, self.data = pm, pm.createData()
        joints = [pm.joints[pm.getJointId(j)] for j in self.free_joints]
        self.idx_q = np.array([j.idx_q for j in joints], dtype=np.int64)
        self.nq = np.array([j.nq for j in joints], dtype=np.int64)
        self.idx_v = np.array([j.idx_v for j in joints], dtype=np.int64)
        self.tree_joints, self.tree_frames = tree_tables(pm, model, self.free_joints)
        # links: each URDF link's frame (its joint, its placement there); those with mass
        self.frame_id = {link: pm.getFrameId(link, pin.BODY) for link in self.link_names}
        self.massive_links = np.array([i for i, link in enumerate(model.links) if link.mass > 0.0], dtype=np.int64)
        joint_of, rows, placements = link_rows(pm, model, self.massive_links, self.frame_id, self.drag_k)
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
        self.summary = np.zeros(25)  # (tree_outputs.body_summary's: pose, twist, CoM, momentum)
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
        return conversions.from_pinocchio(ddq, self.v_pin, self.rotation, self.idx_v, np.empty(self.ndofs))

    def inverse_mass(self) -> np.ndarray:
        if not self.synced:
            self._sync()
        upper = self.pin.computeMinverse(self.pm, self.data, self.q_pin)
        return conversions.world_inverse_mass(upper, self.rotation, self.idx_v)
