"""What a Pinocchio body gives out at its state (the engine's side of :class:`components.dynamics.bodies.Body`'s
outputs): base pose, CoM and momentum (``tree_outputs.body_summary``, compiled), link frames, the
environment's wrenches per link (``tree_forces.tree_generalized_forces``) and a grasp's point
Jacobian and bias; a mixin of :class:`components.dynamics.pinocchio_body.PinocchioBody`, whose state
(``_sync``) it reads.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from components.constants import EARTH_RATE, R_EARTH
from components.dynamics import pinocchio_conversions as conversions
from components.dynamics import pinocchio_kernels as kernels
from components.dynamics import tree_forces
from components.dynamics.bodies import Body

_RIGID_STATE = np.r_[0:16, 19:25]  # the summary's position, orientation, twist, com, momentum


class PinocchioOutputs(Body):
    """The outputs of :class:`components.dynamics.pinocchio_body.PinocchioBody` (its ``_sync``'d state)."""

    # what PinocchioBody holds and this reads (pinocchio has no stubs: its module, model, data)
    pin: Any
    pm: Any
    data: Any
    frame_id: dict[str, int]
    idx_v: np.ndarray
    x: np.ndarray
    v: np.ndarray
    q_pin: np.ndarray
    v_pin: np.ndarray
    rotation: np.ndarray
    summary: np.ndarray
    ints: np.ndarray  # the pooled arrays (PinocchioBody.pool)
    values: np.ndarray
    tree_joints: np.ndarray
    tree_frames: np.ndarray
    tree_links: np.ndarray
    link_joint: np.ndarray
    massive_links: np.ndarray
    wrenches: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    terms: np.ndarray
    atmosphere: np.ndarray
    facets: np.ndarray
    third: np.ndarray
    no_third: np.ndarray
    stage: int
    synced: bool
    summarized: bool
    jacobians: bool

    def _sync(self) -> None:
        """x, v formed, Pinocchio's q, v, tau and R_W_base at them (PinocchioBody's)."""
        raise NotImplementedError

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

    def state_vector(self) -> np.ndarray:
        o = self._summary()
        if self.ndofs == 6:  # no joints: one gather from the summary
            return o[_RIGID_STATE]
        return np.concatenate(
            (o[0:13], self.joint_positions(self.x), self.joint_velocities(self.v), o[13:16], o[19:25])
        )

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
                tree_forces.tree_generalized_forces(
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
        return conversions.world_point_jacobian(J, r, self.rotation, self.idx_v)

    def point_bias(self, link: str, point: np.ndarray) -> np.ndarray:
        """Pinocchio's forward kinematics at the acceleration that is zero in the world's
        coordinates (``zero_world_acceleration``)."""
        pin = self.pin
        if not self.synced:
            self._sync()
        a = conversions.zero_world_acceleration(self.v_pin)
        pin.forwardKinematics(self.pm, self.data, self.q_pin, self.v_pin, a)  # (the same q: data.J holds)
        frame = self.frame_id[link]
        r = pin.updateFramePlacement(self.pm, self.data, frame).rotation @ point
        acceleration = pin.getFrameClassicalAcceleration(self.pm, self.data, frame, pin.LOCAL_WORLD_ALIGNED)
        w = pin.getFrameVelocity(self.pm, self.data, frame, pin.LOCAL_WORLD_ALIGNED).angular
        return conversions.point_acceleration(acceleration.linear, acceleration.angular, w, r)
