r"""Computed-torque control of a free-floating manipulator with the Generalized Jacobian
(Ramón, Pomares, Felicetti, IAC-22, eqs. 6 and 8; the model's terms M*, C*, J_g and the drift,
eqs. 1-7, are derived in :mod:`components.controller.free_floating_arm`). Plain classes, no bus,
no I/O.

Control law, eqs. (6) and (8): with ``e = (p_d - p, log(R_d R^T))`` and
``edot = (v_d - v_e, w_d - w_e)``,

    xddot_r = xddot_d + K_d edot + K_p e                                   (per axis gains)
    qdd*    = J_g^+ (xddot_r - a_drift) + N qdd_0,  qdd_0 = k_np (q_posture - q) - k_nd qdot
    tau     = M* qdd* + C*

``J_g^+`` is a damped least-squares inverse ``V diag(s / (s^2 + lambda^2)) U^T`` with
``lambda^2 = lambda_max^2 (1 - (s_min / eps)^2)`` when ``s_min < eps`` (else 0). ``N = I - V_6 V_6^T``
projects onto J_g's null space (7-DOF arm, 6-D task: one self-motion), where a posture/damping
term holds the arm near its initial posture. The torques are clipped to the URDF effort limits.

``base_model: fixed`` is the textbook fixed-base computed torque on the same measurements (the
base is assumed not to accelerate): ``M* = M_mm``, ``C* = c_m``, ``J_g = J_m``, ``a_drift = Jdot_m
qdot``. It ignores the base's reaction; it is there to show what the free-floating model buys.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dgesdd

from components.controller import kernels
from components.controller.free_floating_arm import ArmState, FreeFloatingArm
from components.controller.trajectory import Hold, PoseSample
from components.rotations import matrix_to_quat

BASE_MODELS = ("free_floating", "fixed")


def compile_kernels(arm: FreeFloatingArm, law: ComputedTorqueLaw) -> None:
    """Compile the numba kernels of a control step (or load them from numba's disk cache) now, by
    one step's calls with ``arm`` at rest in its neutral configuration. A component whose first
    control step comes late (a capture's approach, seconds into the run) calls it at construction:
    a cold compile (~3 s on one idle core) then counts against run.start_timeout, not inside a
    step against run.step_timeout. ``arm`` and ``law`` are throwaway: their state changes."""
    q = np.zeros(arm.n_body)
    for k, _, value in arm._locked_body:
        q[k] = value
    arm.set_state(np.zeros(3), (0.0, 0.0, 0.0, 1.0), np.zeros(6), q, np.zeros(arm.n_body))
    s = arm.compute(law.base_model)
    still = np.zeros(3)
    law.control(s, PoseSample(s.p, still, still, s.R, still, still), s.q.copy())
    dls_inverse(s.J_g, law.eps, law.lam)


def dls_inverse(J: np.ndarray, eps: float, lambda_max: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Damped least-squares inverse of J (m x n, m <= n): (J^+, null-space projector, s_min).

    Damping ``lambda^2 = lambda_max^2 (1 - (s_min/eps)^2)`` only when s_min < eps (Chiaverini's
    variable damping); the projector ``I - V_m V_m^T`` is exact whatever the damping.
    """
    U, s, Vt, s_min, lam2 = damped_svd(J, eps, lambda_max)
    J_plus, N = kernels.pseudo_inverse(U, s, Vt, lam2)
    return J_plus, N, s_min


def damped_svd(J: np.ndarray, eps: float, lambda_max: float):
    """(U, s, Vt, s_min, lambda^2): J's thin SVD and the damping of ``dls_inverse``."""
    # LAPACK's gesdd (as numpy's svd) called directly: numpy's wrapper costs more than the
    # decomposition of a 6x7 matrix
    U, s, Vt, info = dgesdd(J, compute_uv=1, full_matrices=0)  # Vt: the first m rows of V^T
    if info != 0:
        raise np.linalg.LinAlgError(f"SVD did not converge (LAPACK dgesdd info {info})")
    s_min = float(s[-1])
    lam2 = lambda_max**2 * (1.0 - (s_min / eps) ** 2) if s_min < eps else 0.0
    return U, s, Vt, s_min, lam2


@dataclass
class ControlOutput:
    """One control step: arm torques and diagnostics.

    | field | unit | meaning |
    |---|---|---|
    | tau | N m | arm joint torques, ``arm_joints`` order, clipped to the effort limits |
    | error | m, rad | (p_d - p, log(R_d R^T)), W |
    | sigma_min | - | smallest singular value of J_g (J_m for ``fixed``) |
    | qdd | rad/s^2 | the commanded joint acceleration |
    """

    tau: np.ndarray
    error: np.ndarray
    sigma_min: float
    qdd: np.ndarray


class ComputedTorqueLaw:
    """Eqs. (6) and (8) with a damped pseudo-inverse and a null-space posture term.

    | argument | unit | meaning |
    |---|---|---|
    | kp | 1/s^2 (6) | Cartesian stiffness per axis: x, y, z (position), then rotation x, y, z |
    | kd | 1/s (6) | Cartesian damping per axis |
    | null_kp | 1/s^2 (n) | posture stiffness in the null space |
    | null_kd | 1/s (n) | joint damping in the null space |
    | dls_threshold | - | s_min below which the pseudo-inverse is damped (eps) |
    | dls_damping | - | damping at s_min = 0 (lambda_max) |
    | effort | N m (n) | torque limits (URDF) |
    | base_model | - | free_floating (paper) or fixed (ignores the base's reaction) |
    """

    def __init__(
        self,
        kp,
        kd,
        null_kp,
        null_kd,
        effort,
        *,
        dls_threshold: float = 0.02,
        dls_damping: float = 0.05,
        base_model: str = "free_floating",
    ):
        import pinocchio as pin

        if base_model not in BASE_MODELS:
            raise ValueError(f"base_model: expected one of {', '.join(BASE_MODELS)}, got {base_model!r}")
        self.kp, self.kd = np.asarray(kp, dtype=float), np.asarray(kd, dtype=float)
        self.null_kp, self.null_kd = np.asarray(null_kp, dtype=float), np.asarray(null_kd, dtype=float)
        self.effort = np.asarray(effort, dtype=float)
        self.eps, self.lam = float(dls_threshold), float(dls_damping)
        self.base_model = base_model
        self._log3 = pin.log3  # log of SO(3): on one 3x3 a tenth of rotations.log_so3's cost

    def control(self, s: ArmState, d: PoseSample, q_posture: np.ndarray) -> ControlOutput:
        """error = (p_d - p, log(R_d R^T)); xdd_r = xdd_d + K_d edot + K_p e;
        qdd = J_g^+ (xdd_r - a_drift) + N qdd_0 with qdd_0 = k_np (q_posture - q) - k_nd qd;
        tau = M* qdd + C*, clipped to the efforts (kernels.law)."""
        U, sv, Vt, s_min, lam2 = damped_svd(s.J_g, self.eps, self.lam)
        tau, error, qdd = kernels.law(
            U,
            sv,
            Vt,
            lam2,
            d.p,
            s.p,
            self._log3(d.R @ s.R.T),
            d.v,
            d.w,
            d.a,
            d.dw,
            s.xdot,
            self.kp,
            self.kd,
            s.a_drift,
            self.null_kp,
            self.null_kd,
            q_posture,
            s.q,
            s.qd,
            s.M_star,
            s.C_star,
            self.effort,
        )
        return ControlOutput(tau, error, s_min, qdd)


class ArmController:
    """The whole controller of one arm: model, trajectory, law (no I/O; the component wraps it).

    ``start(t, state)`` anchors the trajectory at the measured end-effector pose and takes the
    arm's posture for the null-space term; ``step(t, state)`` returns the outputs for the state
    measured at t (``state`` = position, orientation, twist, q, qd as published by the dynamics).
    The returned ``tau`` covers the whole body (URDF joint order), zero on joints not driven.
    """

    def __init__(
        self,
        arm: FreeFloatingArm,
        law: ComputedTorqueLaw,
        trajectory_spec: Mapping,
        reach: tuple[str, float] | None = None,
    ):
        self.arm, self.law, self.spec = arm, law, trajectory_spec
        self.reach = reach  # (centre joint, reach m) for the out-of-reach check
        self.trajectory: Hold | None = None
        self.q_posture = np.zeros(arm.n)
        self.anchor: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # p0 (3), R0 (3x3), R_base0 (3x3)

    def start(self, state: Mapping[str, np.ndarray]) -> None:
        from components.controller.trajectory import build_cartesian
        from components.errors import ConfigError

        self.arm.set_state(state["position"], state["orientation"], state["twist"], state["q"], state["qd"])
        p0, R0 = self.arm.pose()
        self.q_posture = np.asarray(state["q"], dtype=float)[self.arm.body_arm].copy()
        self.anchor = (p0, R0, self.arm.R_base)
        self.trajectory = build_cartesian(self.spec, *self.anchor)
        if self.reach is not None:
            joint, reach = self.reach
            centre = self.arm.joint_origin(joint)
            for key, point in self.trajectory.checkpoints():
                distance = float(np.linalg.norm(point - centre))
                if distance > reach:
                    raise ConfigError(
                        f"trajectory.{key}",
                        f"out of reach: the path passes {distance:.3f} m from "
                        f"{joint}, the arm reaches at most {reach:.3f} m",
                    )

    def restore(self, p0, R0, R_base0, q_posture) -> None:
        """Take a saved anchor and posture (the component's set_state): the same trajectory as
        the instance that saved them, without ``start``'s measurement and reach check."""
        from components.controller.trajectory import build_cartesian

        self.anchor = (np.asarray(p0, float), np.asarray(R0, float), np.asarray(R_base0, float))
        self.q_posture = np.asarray(q_posture, dtype=float).copy()
        self.trajectory = build_cartesian(self.spec, *self.anchor)

    def step(self, t: float, state: Mapping[str, np.ndarray]) -> dict[str, np.ndarray | np.float64]:
        self.arm.set_state(state["position"], state["orientation"], state["twist"], state["q"], state["qd"])
        s = self.arm.compute(self.law.base_model)
        assert self.trajectory is not None, "start or restore comes first"
        d = self.trajectory.sample(t)
        out = self.law.control(s, d, self.q_posture)
        tau = np.zeros(self.arm.n_body)
        tau[self.arm.body_arm] = out.tau
        return {
            "tau": tau,
            "ee_position": s.p,
            "ee_position_desired": d.p,
            "ee_error": out.error,
            "ee_orientation": s.quat,
            "ee_orientation_desired": matrix_to_quat(d.R),
            "ee_twist": s.xdot,
            "sigma_min": np.float64(out.sigma_min),
        }
