"""A body's dynamics by DART: its skeleton on a FreeJoint, whose chart is the world's coordinates.

DART's FreeJoint positions are the base rotation vector and origin, its velocities the world-frame
angular velocity and the origin's velocity: the world's coordinates (components/dynamics/bodies.py)
up to the order of the joints, which DART may number otherwise than the URDF (then ``order`` maps
them; for the shipped models it is the identity and nothing is copied).

The environment: a link welded to its parent (fixed URDF joint, locked joint) moves with its
anchor, the nearest ancestor that is not welded (or itself). It takes one DART call per anchor,
its Jacobian, which gives the anchor's pose and maps the wrench of its links to generalized
forces (``anchor_forces.generalized_forces``: no DART call per link and wrench). The skeleton is
loaded from the URDF in :mod:`components.dynamics.dart_skeleton`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from components.constants import EARTH_RATE, R_EARTH
from components.dynamics import anchor_forces, link_forces, manifold_rk4
from components.dynamics.bodies import Body, BodySpec, Environment
from components.dynamics.dart_skeleton import load_skeleton
from components.robots.urdf import UrdfModel
from components.rotations import cross3, rpy_to_matrix

ORIGIN = np.zeros(3)


class DartBody(Body):
    """A body as a DART skeleton (``skel``); ``nodes``: its body nodes with mass."""

    engine = "dart"

    def __init__(self, spec: BodySpec, model: UrdfModel, environment: Environment, dart, integrator: str = "rk4"):
        super().__init__(spec, model, environment)
        self.dart = dart
        frames = model.frame_links()
        skel, self.engine_notes = load_skeleton(spec, model, self.locked, dart)
        self.skel = skel
        dof_names = [skel.getDof(i).getName() for i in range(skel.getNumDofs())]
        # DART's dof of each coordinate; None when they agree (the usual case)
        order = np.array(list(range(6)) + [dof_names.index(j) for j in self.free_joints], dtype=int)
        identity = np.array_equal(order, np.arange(self.ndofs))
        self.order = None if identity else order
        self.dart_order = None if identity else np.argsort(order)  # DART dof -> coordinate
        for i in range(6, self.ndofs):  # no joint friction, springs or damping
            dof = skel.getDof(i)
            dof.setDampingCoefficient(0.0)
            dof.setCoulombFriction(0.0)
            dof.setSpringStiffness(0.0)
        mimic_joints = {self.free_joints[k - 6] for k, _, _, _ in self.mimic}
        for joint in (skel.getJoint(j) for j in mimic_joints):  # rk4 projects; dart keeps DART's MIMIC actuator
            if joint.getActuatorType() == dart.dynamics.ActuatorType.MIMIC and integrator == "rk4":
                joint.setActuatorType(dart.dynamics.ActuatorType.FORCE)
        # links: DART body nodes with mass (environment), URDF link order (outputs)
        nodes = {skel.getBodyNode(i).getName(): skel.getBodyNode(i) for i in range(skel.getNumBodyNodes())}
        self.nodes = [bn for bn in nodes.values() if bn.getMass() > 0.0]
        self.has_massless = len(self.nodes) < len(nodes)
        self.mass = np.array([bn.getMass() for bn in self.nodes])
        self.local_com = np.array([bn.getLocalCOM() for bn in self.nodes]).reshape(-1, 3)
        self.local_inertia = np.array([bn.getInertia().getMoment() for bn in self.nodes]).reshape(-1, 3, 3)
        self.total_mass = float(self.mass.sum())
        link_in_anchor = self._anchor_tables()
        self.root = skel.getRootBodyNode()
        node_slot = {bn.getName(): i for i, bn in enumerate(self.nodes)}
        self.link_source: list[tuple[Any, int, np.ndarray | None]] = []  # (node, env slot or -1, fixed offset or None)
        for link in self.link_names:
            if link in frames:
                joint = frames[link]
                T = np.eye(4)
                T[:3, :3], T[:3, 3] = rpy_to_matrix(joint.rpy), joint.xyz
                self.link_source.append((nodes[joint.parent], -1, T))
            else:
                self.link_source.append((nodes[link], node_slot.get(link, -1), None))
        self.massive_links = np.array([i for i, (_, slot, _) in enumerate(self.link_source) if slot >= 0], dtype=int)
        self.massive_slots = np.array([slot for _, slot, _ in self.link_source if slot >= 0], dtype=int)
        self.node_drag_k = np.array([self.drag_k.get(bn.getName(), 0.0) for bn in self.nodes])
        self.srp_links, self.srp_facet_rows = self.srp_tables(
            [bn.getName() for bn in self.nodes],
            [T[:3, :3] for T in link_in_anchor],
            [T[:3, 3] - c for T, c in zip(link_in_anchor, self.com_in_anchor)],
        )
        self.light = environment.light()  # the Sun and Moon: world.set_sun
        self.third = environment.third()  # the third bodies' GMs (0: off)
        self.no_third = np.zeros(2)
        self.force = np.zeros((len(self.nodes), 3))  # environment per link, anchor axes
        self.torque = np.zeros((len(self.nodes), 3))
        self.dart_tau = self.tau  # tau in DART's order
        self.forces_are_tau = False  # the skeleton's forces are tau alone
        self.world_frame = dart.dynamics.Frame.World()

    def _anchor_tables(self) -> list[np.ndarray]:
        """Each massive node's anchor (the nearest ancestor not welded to its parent, or itself), its
        CoM and inertia in the anchor's axes; the anchors' Jacobian columns side by side. Returns
        each node's transform in its anchor's frame."""
        anchor_index: dict[str, int] = {}
        self.anchors: list[Any] = []  # DART body nodes
        slots, com_in_anchor, inertia_in_anchor, link_in_anchor = [], [], [], []
        for bn, com, inertia in zip(self.nodes, self.local_com, self.local_inertia):
            anchor, T = bn, np.eye(4)
            while anchor.getParentJoint().getType() == "WeldJoint":
                T = anchor.getParentJoint().getRelativeTransform().matrix() @ T
                anchor = anchor.getParentBodyNode()
            if anchor.getName() not in anchor_index:
                anchor_index[anchor.getName()] = len(self.anchors)
                self.anchors.append(anchor)
            slots.append(anchor_index[anchor.getName()])
            com_in_anchor.append(T[:3, :3] @ com + T[:3, 3])
            inertia_in_anchor.append(T[:3, :3] @ inertia @ T[:3, :3].T)
            link_in_anchor.append(T)
        self.anchor_slot = np.array(slots, dtype=int)
        self.com_in_anchor = np.array(com_in_anchor).reshape(-1, 3)
        self.inertia_in_anchor = np.array(inertia_in_anchor).reshape(-1, 3, 3)
        # columns of the anchors' Jacobians side by side: their dof, their anchor; and the
        # columns of the base rotation (the FreeJoint's first three dofs come first in each)
        dofs = [
            [anchor.getDependentGenCoordIndex(i) for i in range(anchor.getNumDependentGenCoords())]
            for anchor in self.anchors
        ]
        self.jacobian_dofs = np.array([dof for anchor_dofs in dofs for dof in anchor_dofs], dtype=int)
        self.jacobian_anchor = np.repeat(
            np.arange(len(self.anchors)), [len(anchor_dofs) for anchor_dofs in dofs]
        ).astype(int)
        starts = np.cumsum([0] + [len(anchor_dofs) for anchor_dofs in dofs[:-1]])
        self.base_rotation_columns = (starts[:, None] + np.arange(3)).astype(int)
        return link_in_anchor

    # -- state
    def base_coordinates(self, R, p) -> np.ndarray:
        T = self.dart.math.Isometry3()
        T.set_rotation(R)
        T.set_translation(p)
        return self.dart.dynamics.FreeJoint.convertToPositions(T)

    def positions(self) -> np.ndarray:
        q = self.skel.getPositions()
        return q if self.order is None else q[self.order]

    def velocities(self) -> np.ndarray:
        v = self.skel.getVelocities()
        return v if self.order is None else v[self.order]

    def _dart(self, values: np.ndarray) -> np.ndarray:
        return values if self.order is None else values[self.dart_order]

    def set_state(self, positions, velocities) -> None:
        self.skel.setPositions(self._dart(positions))
        self.skel.setVelocities(self._dart(velocities))

    def set_stage(self, q0, xi, velocities) -> None:
        self.skel.setPositions(self._dart(manifold_rk4.moved(q0, xi)))
        self.skel.setVelocities(self._dart(velocities))

    def set_velocities(self, velocities) -> None:
        self.skel.setVelocities(self._dart(velocities))

    def torques_changed(self) -> None:
        self.dart_tau = self._dart(self.tau)
        self.forces_are_tau = False

    # -- dynamics
    def _environment(
        self,
        R: np.ndarray,
        V: np.ndarray,
        tidal: bool,
        drag: bool,
        srp: bool,
        gravity_gradient=None,
        third: bool = True,
    ):
        """The body's generalized forces (DART order), its joint torques and the environment with the
        reference point at (R, V), which also fills ``force`` and ``torque``; and the anchors'
        Jacobians side by side. ``third``: the third bodies the environment has (else none)."""
        J = np.concatenate([anchor.getJacobian(ORIGIN) for anchor in self.anchors], axis=1)
        drag = drag and self.has_drag
        v_com = np.array([bn.getCOMLinearVelocity() for bn in self.nodes]).reshape(-1, 3) if drag else self.force
        e = self.environment
        atmosphere = e.atmosphere
        forces = anchor_forces.generalized_forces(
            J,
            self.base_rotation_columns,
            self.jacobian_anchor,
            self.jacobian_dofs,
            self.anchor_slot,
            self.com_in_anchor,
            self.inertia_in_anchor,
            self.mass,
            R,
            V,
            self.skel.getPositions()[3:6],
            e.mu,
            tidal,
            e.gravity_gradient if gravity_gradient is None else gravity_gradient,
            drag,
            self.node_drag_k,
            v_com,
            atmosphere.h0,
            atmosphere.rho0,
            atmosphere.scale,
            EARTH_RATE,
            R_EARTH,
            self.dart_tau,
            self.force,
            self.torque,
            srp and self.has_srp,
            self.light,
            self.srp_links,
            self.srp_facet_rows,
            self.third if third else self.no_third,
        )
        return forces, J

    def set_forces(self, reference) -> None:
        """The skeleton's generalized forces: tau, and the environment unless ``reference`` is None."""
        if reference is not None:
            point, s = reference
            R, V = link_forces.propagate_reference(point[:3], point[3:], s, self.environment.mu)
            forces, _ = self._environment(R, V, self.environment.tidal, self.environment.drag, self.environment.srp)
            self.skel.setForces(forces)
            self.forces_are_tau = False
        elif not self.forces_are_tau:  # forward dynamics leaves them: set once
            self.skel.setForces(self.dart_tau)
            self.forces_are_tau = True

    def forward_dynamics(self, reference) -> np.ndarray:
        self.set_forces(reference)
        skel = self.skel
        skel.computeForwardDynamics()
        a = skel.getAccelerations()
        return a if self.order is None else a[self.order]

    def inverse_mass(self) -> np.ndarray:
        """M^-1. DART's getInvMassMatrix is wrong (off by O(1)) when a body node has zero mass (a
        URDF's massless flange between two links, say): then M is inverted."""
        Minv = np.linalg.inv(self.skel.getMassMatrix()) if self.has_massless else self.skel.getInvMassMatrix()
        return Minv if self.order is None else Minv[np.ix_(self.order, self.order)]

    # -- outputs
    def base_pose(self):
        T = self.root.getTransform()
        return T.rotation(), T.translation()

    def com(self) -> np.ndarray:
        return self.skel.getCOM()

    def com_velocity(self) -> np.ndarray:
        return self.skel.getCOMLinearVelocity()

    def momentum(self, com: np.ndarray, base_position: np.ndarray) -> np.ndarray:
        """The base rows of M(q) v are the momentum conjugate to the FreeJoint velocity (omega_W,
        v_W): total angular momentum about the base origin p, then linear momentum L; about the
        CoM c: H_c = H_p - (c - p) x L. (DART builds M in C++ faster than the link sum could gather
        each link's pose and velocity through Python.)"""
        h = self.skel.getMassMatrix()[:6] @ self.skel.getVelocities()
        linear = h[3:6]
        return np.concatenate([linear, h[:3] - cross3(com - base_position, linear)])

    def link_transforms(self) -> np.ndarray:
        T = np.array([bn.getTransform().matrix() for bn, _, _ in self.link_source])
        for i, (_, _, offset) in enumerate(self.link_source):
            if offset is not None:
                T[i] = T[i] @ offset
        return T

    def environment_wrenches(self, R, V):
        R, V = np.asarray(R, dtype=float), np.asarray(V, dtype=float)
        e = self.environment
        _, J = self._environment(R, V, e.tidal, False, False, third=False)
        tidal, torque = self.force.copy(), self.torque.copy()
        drag = np.zeros_like(tidal)
        if e.drag and self.has_drag:
            self._environment(R, V, False, True, False, third=False)
            drag = self.force.copy()
        return self._per_link(J, (tidal, drag, torque))

    def srp_wrenches(self, R, V):
        R, V = np.asarray(R, dtype=float), np.asarray(V, dtype=float)
        _, J = self._environment(R, V, False, False, True, gravity_gradient=False, third=False)
        return self._per_link(J, (self.force.copy(), self.torque.copy()))

    def third_body_forces(self, R, V):
        R, V = np.asarray(R, dtype=float), np.asarray(V, dtype=float)
        _, J = self._environment(R, V, False, False, False, gravity_gradient=False)
        return self._per_link(J, (self.force.copy(),))[0]

    def _per_link(self, J, wrenches):
        """Per URDF link, W axes, of the massive links' ``wrenches`` in anchor axes."""
        # R_a^T: the angular rows of each anchor's base rotation columns
        rotation_T = J[:3].take(self.base_rotation_columns, axis=1).transpose(1, 0, 2).take(self.anchor_slot, axis=0)
        out = []
        for local in wrenches:
            per_link = np.zeros((len(self.link_names), 3))
            per_link[self.massive_links] = np.einsum("nji,nj->ni", rotation_T, local)[self.massive_slots]
            out.append(per_link)
        return tuple(out)

    # -- a grasp
    def _node_point(self, link: str, point: np.ndarray):
        node, _, offset = self.link_source[self.link_names.index(link)]
        if offset is not None:
            point = offset[:3, :3] @ point + offset[:3, 3]
        return node, point

    def link_pose(self, link: str):
        node, _, offset = self.link_source[self.link_names.index(link)]
        T = node.getTransform().matrix()
        if offset is not None:
            T = T @ offset
        return T[:3, 3].copy(), T[:3, :3].copy()

    def point_jacobian(self, link: str, point: np.ndarray) -> np.ndarray:
        """Over all of the body's dofs (a node's own Jacobian spans only the dofs it depends on)."""
        node, point = self._node_point(link, point)
        J = self.skel.getWorldJacobian(node, point)
        return J if self.order is None else J[:, self.order]

    def point_bias(self, link: str, point: np.ndarray) -> np.ndarray:
        node, point = self._node_point(link, point)
        return self.skel.getJacobianClassicDeriv(node, point, self.world_frame) @ self.skel.getVelocities()
