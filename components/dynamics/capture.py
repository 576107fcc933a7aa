"""The grasp of a capture: a chaser's end effector welded to a target's grasp frame.

Two free-floating bodies (of any engine: components/dynamics/bodies.py) become one rigid assembly
when the grasp closes. The weld is a bilateral constraint between a point P fixed in both bodies (the end
effector's origin at the capture instant) and their relative attitude, solved at every
integrator stage by a constraint wrench lambda (torque, force about P; W axes) on the chaser and
its opposite on the target:

    K lambda = -(J_c a_c + Jdot_c v_c - J_t a_t - Jdot_t v_t) - 2 w_n e_v - w_n^2 e_x,
    K = J_c M_c^-1 J_c^T + J_t M_t^-1 J_t^T,
    a_c += M_c^-1 J_c^T lambda,   a_t -= M_t^-1 J_t^T lambda,

where J are the world Jacobians of P (rows: angular, linear), a the accelerations without the
constraint, Jdot v the classical bias accelerations, e_v and e_x the relative twist and pose
(Baumgarte terms, which only remove the integrator's drift). The wrench acts at one point with
opposite signs, so the total linear and angular momentum are untouched by it.

Closing the grasp is an inelastic impact: the velocity-level twin of the same equation, an
impulse that cancels the relative twist at P, again equal and opposite (momentum conserved
exactly, whatever the residual relative velocity).

Frames: the end effector E and the grasp frame G are URDF links (a frame link on a fixed joint is
fine); the weld's state (P, the relative attitude) is held in their frames, the same for every
engine. Outputs use E's axes: ``p_ee_grasp`` (G's origin in E), ``q_ee_grasp`` (q_E_G) and the
relative twist of G seen from E.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from components.dynamics import manifold_rk4
from components.rotations import cross3, matrix_to_quat

#: Baumgarte stabilization: w_n = BAUMGARTE / dt, critically damped. It only removes integration
#: drift (~1e-12 m per step), so its value barely matters; w_n dt = 0.1 keeps RK4 well inside its
#: stability region.
BAUMGARTE = 0.1


@dataclass(frozen=True)
class Tolerance:
    """When the grasp may close: pose and velocity errors between E and G (m, rad, m/s, rad/s)."""

    position: float
    orientation: float
    linear_velocity: float
    angular_velocity: float


OVERLOAD_ACTIONS = ("release", "hold")


@dataclass(frozen=True)
class GraspSpec:
    """``chaser``'s link ``end_effector`` grasps ``target``'s link ``grasp_frame``. The fixture
    carries at most ``force_limit`` (N) and ``torque_limit`` (N m, about the grasp point); beyond
    either the weld opens (``on_overload: release``) or stays closed (``hold``)."""

    chaser: str
    end_effector: str
    target: str
    grasp_frame: str
    tolerance: Tolerance
    force_limit: float = math.inf
    torque_limit: float = math.inf
    on_overload: str = "release"


@dataclass
class CaptureReport:
    """What the closing impact was: the relative twist it cancelled (target relative to chaser at
    P: linear m/s, angular rad/s, W axes) and the impulse the chaser gave the target (linear N s,
    angular N m s about P, W axes)."""

    relative_twist: np.ndarray
    impulse: np.ndarray
    errors: dict


class _Frame:
    """A URDF link of a body (any engine's: components/dynamics/bodies.py)."""

    def __init__(self, body, link: str):
        self.body, self.link = body, link

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(p, R) of the link in W."""
        return self.body.link_pose(self.link)

    def jacobian(self, point: np.ndarray) -> np.ndarray:
        """World Jacobian (rows: angular, linear) of the link's material point over all of the
        body's coordinates."""
        return self.body.point_jacobian(self.link, point)

    def bias(self, point: np.ndarray) -> np.ndarray:
        """That point's acceleration at zero accelerations: Jdot v (angular, linear; W)."""
        return self.body.point_bias(self.link, point)

    def point_in_link(self, p_W: np.ndarray) -> np.ndarray:
        """A point given in W, in the link's frame."""
        p, R = self.pose()
        return R.T @ (p_W - p)


def _twist(frame: _Frame, point: np.ndarray) -> np.ndarray:
    """World (angular, linear) velocity of the link's material point."""
    return frame.jacobian(point) @ frame.body.velocities()


class Grasp:
    """The grasp between two bodies of an OrbitalWorld; ``closed`` once captured.

    ``errors()`` measures E against G; ``close()`` welds them (the impact); while closed,
    ``constrain(accelerations, dt)`` adds the constraint to the bodies' stage accelerations and
    ``project()`` restores the velocity constraint after a joint-stop impulse."""

    def __init__(self, spec: GraspSpec, chaser, target):
        self.spec = spec
        self.ee = _Frame(chaser, spec.end_effector)
        self.grasp = _Frame(target, spec.grasp_frame)
        self.closed = False
        self.p_in_chaser = np.zeros(3)  # P in the end effector's link frame E
        self.p_in_target = np.zeros(3)  # P in the grasp frame G
        self.R_target_chaser = np.eye(3)  # E's attitude in G's, welded
        self.wrench = np.zeros(6)  # last constraint wrench on the chaser (angular, linear; W, about P)
        self.peak = np.zeros(2)  # largest |force| (N) and |torque| (N m) of the weld since reset_peak
        self.armed = True  # closes when asked; False after a release until close is lowered
        self.overloaded = False  # the last step was beyond the load limits

    # ------------------------------------------------------------------ measuring

    def relative(self) -> dict[str, np.ndarray]:
        """G relative to E: ``p_ee_grasp`` (m, E axes), ``q_ee_grasp`` (q_E_G) and ``twist_ee_grasp``
        (the rate of p_ee_grasp in E (m/s), then G's angular velocity relative to E (rad/s), E axes)."""
        p_E, R_E = self.ee.pose()
        p_G, R_G = self.grasp.pose()
        w_E, v_E = np.split(_twist(self.ee, self.ee.point_in_link(p_E)), 2)
        w_G, v_G = np.split(_twist(self.grasp, self.grasp.point_in_link(p_G)), 2)
        d = p_G - p_E
        linear = v_G - v_E - cross3(w_E, d)
        return {
            "p_ee_grasp": R_E.T @ d,
            "q_ee_grasp": matrix_to_quat(R_E.T @ R_G),
            "twist_ee_grasp": np.concatenate([R_E.T @ linear, R_E.T @ (w_G - w_E)]),
        }

    def errors(self) -> dict[str, float]:
        """Pose and velocity errors between E and G: distance of the origins (m), attitude angle
        (rad), and the target's velocity relative to the chaser at E's origin (m/s, rad/s)."""
        p_E, R_E = self.ee.pose()
        p_G, R_G = self.grasp.pose()
        relative = self._relative_twist(p_E)
        cos = np.clip((np.trace(R_E.T @ R_G) - 1.0) / 2.0, -1.0, 1.0)
        return {
            "position": float(np.linalg.norm(p_G - p_E)),
            "orientation": float(math.acos(cos)),
            "linear_velocity": float(np.linalg.norm(relative[3:])),
            "angular_velocity": float(np.linalg.norm(relative[:3])),
        }

    def within_tolerance(self) -> bool:
        tol = self.spec.tolerance
        e = self.errors()
        return (
            e["position"] <= tol.position
            and e["orientation"] <= tol.orientation
            and e["linear_velocity"] <= tol.linear_velocity
            and e["angular_velocity"] <= tol.angular_velocity
        )

    def _relative_twist(self, p_W: np.ndarray) -> np.ndarray:
        """Target minus chaser velocity at the point p_W (angular, linear; W)."""
        return _twist(self.grasp, self.grasp.point_in_link(p_W)) - _twist(self.ee, self.ee.point_in_link(p_W))

    # ------------------------------------------------------------------ the weld

    def close(self) -> CaptureReport:
        """Weld E to G where they are now, with the impact that cancels their relative twist."""
        errors = self.errors()
        p_E, R_c = self.ee.pose()
        _, R_t = self.grasp.pose()
        self.p_in_chaser = self.ee.point_in_link(p_E)
        self.p_in_target = self.grasp.point_in_link(p_E)
        self.R_target_chaser = R_t.T @ R_c
        relative = self._relative_twist(p_E)
        impulse = self.project()
        self.closed = True
        # the impulse on the target is the opposite of the chaser's: (linear, angular) for the report
        return CaptureReport(
            relative_twist=np.concatenate([relative[3:], relative[:3]]),
            impulse=-np.concatenate([impulse[3:], impulse[:3]]),
            errors=errors,
        )

    def _terms(self):
        J_c = self.ee.jacobian(self.p_in_chaser)
        J_t = self.grasp.jacobian(self.p_in_target)
        M_c, M_t = self.ee.body.inverse_mass(), self.grasp.body.inverse_mass()
        MJ_c, MJ_t = M_c @ J_c.T, M_t @ J_t.T
        return J_c, J_t, MJ_c, MJ_t, J_c @ MJ_c + J_t @ MJ_t

    def project(self) -> np.ndarray:
        """Cancel the relative twist at P by an equal and opposite impulse; the chaser's (angular,
        linear; N m s, N s; W)."""
        chaser, target = self.ee.body, self.grasp.body
        v_c, v_t = chaser.velocities(), target.velocities()
        J_c, J_t, MJ_c, MJ_t, K = self._terms()
        impulse = np.linalg.solve(K, -(J_c @ v_c - J_t @ v_t))
        chaser.set_velocities(v_c + MJ_c @ impulse)
        target.set_velocities(v_t - MJ_t @ impulse)
        return impulse

    def pose_error(self) -> np.ndarray:
        """(rotation vector, position) of the chaser's side of the weld relative to the target's, W."""
        p_E, R_E = self.ee.pose()
        p_G, R_G = self.grasp.pose()
        R_err = R_E @ (R_G @ self.R_target_chaser).T
        p_c = R_E @ self.p_in_chaser + p_E
        p_t = R_G @ self.p_in_target + p_G
        return np.concatenate([manifold_rk4.log_so3(np.ascontiguousarray(R_err)), p_c - p_t])

    def constrain(self, a_chaser: np.ndarray, a_target: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The stage accelerations with the weld's wrench added (the skeletons hold the stage state)."""
        v_c, v_t = self.ee.body.velocities(), self.grasp.body.velocities()
        J_c, J_t, MJ_c, MJ_t, K = self._terms()
        bias = self.ee.bias(self.p_in_chaser) - self.grasp.bias(self.p_in_target)
        w_n = BAUMGARTE / dt
        e_v = J_c @ v_c - J_t @ v_t
        rhs = -(J_c @ a_chaser - J_t @ a_target + bias) - 2.0 * w_n * e_v - w_n * w_n * self.pose_error()
        wrench = np.linalg.solve(K, rhs)
        self.wrench = wrench
        self.peak = np.maximum(self.peak, (math.hypot(*wrench[3:]), math.hypot(*wrench[:3])))
        return a_chaser + MJ_c @ wrench, a_target - MJ_t @ wrench

    def wrench_on_target(self) -> np.ndarray:
        """The last constraint wrench as the end effector applies it to the target: force (N),
        torque about P (N m), in E's axes."""
        _, R_E = self.ee.pose()
        return np.concatenate([R_E.T @ -self.wrench[3:], R_E.T @ -self.wrench[:3]])

    # ------------------------------------------------------------------ load limits

    def reset_peak(self) -> None:
        self.peak = np.zeros(2)

    def check_overload(self) -> dict | None:
        """After a step: the overload that began in it (the peaks of the weld's force and torque
        over its stages, the limits and what was done), or None. A release opens the weld (no
        impulse: the momentum of the bodies is untouched) and disarms the grasp until ``close``
        is lowered; ``hold`` keeps it closed. One report per overload: it must fall back within
        the limits before another."""
        spec = self.spec
        over = self.closed and (self.peak[0] > spec.force_limit or self.peak[1] > spec.torque_limit)
        began = over and not self.overloaded
        self.overloaded = over
        if not began:
            return None
        if spec.on_overload == "release":
            self.closed, self.armed, self.overloaded = False, False, False
        return {
            "force": float(self.peak[0]),
            "torque": float(self.peak[1]),
            "force_limit": spec.force_limit,
            "torque_limit": spec.torque_limit,
            "action": spec.on_overload,
        }

    def rearm(self, close: bool) -> None:
        """A released grasp closes again only once ``close`` has been lowered."""
        if not close:
            self.armed = True

    # ------------------------------------------------------------------ state

    def get_state(self) -> dict[str, np.ndarray | np.float64]:
        return {
            "grasp.closed": np.float64(self.closed),
            "grasp.p_in_chaser": self.p_in_chaser.copy(),
            "grasp.p_in_target": self.p_in_target.copy(),
            "grasp.R_target_chaser": self.R_target_chaser.ravel().copy(),
            "grasp.wrench": self.wrench.copy(),
            "grasp.armed": np.float64(self.armed),
            "grasp.overloaded": np.float64(self.overloaded),
        }

    def set_state(self, state) -> None:
        for key, size in (
            ("grasp.closed", 1),
            ("grasp.p_in_chaser", 3),
            ("grasp.p_in_target", 3),
            ("grasp.R_target_chaser", 9),
            ("grasp.wrench", 6),
            ("grasp.armed", 1),
            ("grasp.overloaded", 1),
        ):
            if key not in state or np.size(state[key]) != size:
                raise ValueError(f"state: {key} expected {size} values")
        self.closed = bool(float(state["grasp.closed"]))
        self.p_in_chaser = np.array(state["grasp.p_in_chaser"], dtype=float)
        self.p_in_target = np.array(state["grasp.p_in_target"], dtype=float)
        self.R_target_chaser = np.array(state["grasp.R_target_chaser"], dtype=float).reshape(3, 3)
        self.wrench = np.array(state["grasp.wrench"], dtype=float)
        self.armed = bool(float(state["grasp.armed"]))
        self.overloaded = bool(float(state["grasp.overloaded"]))
