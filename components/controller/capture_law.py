r"""The capture's torques besides the Cartesian law (:class:`ComputedTorqueLaw`, closing and
track): the closing reference, the arm's joint-space moves and holds, and the wheels' detumbling
(issues 23 and 33). Plain classes, no bus, no I/O; the capture controller
(:mod:`components.controller.capture`) picks one per phase.

Closing reference (``closing_reference``)
-----------------------------------------
The estimated grasp frame carrying the end effector's offset at the end of the approach (position
and rotation vector, both in the grasp frame's axes), shrunk to zero by a quintic over
``closing_time``: a straight line along the grapple's axis from the pre-grasp pose, with every
derivative of the reference exact (the grasp frame's velocity and acceleration carried through
the offset).

Joint moves and holds (``JointLaw``)
------------------------------------
Before capture: joint-space computed torque ``tau = M* qdd + C*`` (the base's reaction is in M*
and C*) with ``qdd = qdd_d + K_d (qd_d - qd) + K_p (q_d - q)`` on a joint move, or towards a
still configuration. After capture the arm holds the joint configuration it had then with a joint
PD in torque units and the servicer's Coriolis terms, ``tau = K_p (q_hold - q) - K_d qd + C*``:
the welded target's inertia, which the model lacks (an uncooperative target), dwarfs the
servicer's M* at the wrist (M* times a gain in 1/s^2 would hold the target's load with a few
N m/rad: 0.4 rad of wrist deflection in a detumble). With the one step of delay of a sampled loop
the hold is stable for ``K_d h`` well below the smallest eigenvalue of the assembly's M* (about
5 kg m^2 for models/capture with its 300 kg target: K_d = 100 N m s/rad at h = 10 ms is, 500 is
not) and unstable on the bare arm (M* down to 0.004 kg m^2). Every torque is clipped to the URDF
effort limits.

Detumbling (``WheelLaw``)
-------------------------
The bus torque ``T = -k omega`` from the IMU rate omega (bus axes); a wheel torque tau_j about its
axis a_j puts ``-tau_j a_j`` on the bus, so ``tau = A^+ k omega`` (A = [a_j], bus axes). A wheel at
its URDF speed limit gets no torque that would spin it faster; the torques are scaled together
(direction kept) to the URDF effort limits, then by a factor that keeps the measured wrist wrench
within ``grasp_force_limit``/``grasp_torque_limit``: whenever the wrench exceeds a limit by the
ratio r > 1 the factor is divided by r; otherwise it recovers linearly to 1 over
``wrench_recovery_time``. Total momentum is never an input.

Limits (``LimitWatch``)
-----------------------
While the Cartesian law follows the grapple (closing, track) the arm gives up following it when
the grapple leaves the reach sphere about the shoulder, or when following it needs joint rates
(the Generalized Jacobian's inverse on the reference twist, or the measured rates when larger) or
torques beyond the URDF limits for longer than ``limit_window``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from components.controller.capture_plan import JointMove
from components.controller.capture_settings import CaptureSettings
from components.controller.computed_torque import ComputedTorqueLaw, dls_inverse
from components.controller.free_floating_arm import ArmState, FreeFloatingArm
from components.controller.trajectory import PoseSample, quintic
from components.rotations import exp_so3


def closing_reference(
    t: float, start: float, offset: np.ndarray, rotation: np.ndarray, duration: float, g: PoseSample
) -> PoseSample:
    """The grasp frame g with the end effector's offset and rotation vector at ``start`` (grasp
    frame axes) shrinking to zero by a quintic over ``duration`` (module doc)."""
    s, ds, dds = quintic(t, start, duration)
    f, df, ddf = 1.0 - s, -ds, -dds
    r, dr, ddr = g.R @ (f * offset), g.R @ (df * offset), g.R @ (ddf * offset)
    u, du = g.R @ (df * rotation), g.R @ (ddf * rotation)
    return PoseSample(
        g.p + r,
        g.v + np.cross(g.w, r) + dr,
        g.a + np.cross(g.dw, r) + np.cross(g.w, np.cross(g.w, r)) + 2.0 * np.cross(g.w, dr) + ddr,
        g.R @ exp_so3(f * rotation),
        g.w + u,
        g.dw + np.cross(g.w, u) + du,
    )


class JointLaw:
    """The arm's joint-space torques (module doc): ``follow`` a joint move and ``hold`` a
    configuration by computed torque (``hold_kp``, ``hold_kd``), ``hold_captured`` after capture
    (``captured_kp``, ``captured_kd``), each clipped to ``effort``."""

    def __init__(self, settings: CaptureSettings, effort: np.ndarray):
        self.cfg, self.effort = settings, effort

    def follow(self, move: JointMove, t: float, s: ArmState) -> np.ndarray:
        """Computed torque on the joint move (M*, C*: the base's reaction included)."""
        q_d, qd_d, qdd_d = move.sample(t)
        qdd = qdd_d + self.cfg.hold_kd * (qd_d - s.qd) + self.cfg.hold_kp * (q_d - s.q)
        return self._clip(s.M_star @ qdd + s.C_star)

    def hold(self, s: ArmState, q_hold: np.ndarray) -> np.ndarray:
        """Computed-torque joint hold of the servicer alone (waiting, or given up)."""
        qdd = self.cfg.hold_kp * (q_hold - s.q) - self.cfg.hold_kd * s.qd
        return self._clip(s.M_star @ qdd + s.C_star)

    def hold_captured(self, s: ArmState, q_hold: np.ndarray) -> np.ndarray:
        """Joint PD in torque units plus the servicer's C* (after capture: the target's inertia,
        which the model lacks, dominates M*)."""
        return self._clip(self.cfg.captured_kp * (q_hold - s.q) - self.cfg.captured_kd * s.qd + s.C_star)

    def _clip(self, tau: np.ndarray) -> np.ndarray:
        return np.minimum(np.maximum(tau, -self.effort), self.effort)


class WheelLaw:
    """The wheels' detumbling torques (module doc); ``index`` places them among the body's joints.
    The wrench factor is the caller's state: ``next_scale`` gives its value for the next step."""

    def __init__(self, settings: CaptureSettings, index: np.ndarray):
        self.cfg, self.index = settings, index
        if index.size:
            self.wheel_map = np.linalg.pinv(np.asarray(settings.wheel_axes, dtype=float).reshape(3, -1))
        else:
            self.wheel_map = np.zeros((0, 3))

    def torques(self, rate_imu, qd) -> np.ndarray:
        """The wheel torques that damp the bus rate, within the wheels' speed and effort limits
        (before the wrench factor); ``qd`` the body's joint rates."""
        cfg = self.cfg
        tau = self.wheel_map @ (cfg.detumble_gain * np.asarray(rate_imu, dtype=float))
        qd = np.asarray(qd, dtype=float)[self.index]
        tau[(np.abs(qd) >= cfg.wheel_velocity) & (tau * qd > 0.0)] = 0.0
        ratio = float(np.max(np.abs(tau) / cfg.wheel_effort))
        return tau / ratio if ratio > 1.0 else tau

    def next_scale(self, scale: float, h: float, wrench) -> float:
        """The wrench factor after a control period h with the wrist ``wrench`` measured."""
        cfg = self.cfg
        wrench = np.asarray(wrench, dtype=float)
        excess = max(
            float(np.linalg.norm(wrench[:3])) / cfg.grasp_force_limit,
            float(np.linalg.norm(wrench[3:])) / cfg.grasp_torque_limit,
        )
        return scale / excess if excess > 1.0 else min(1.0, scale + h / cfg.wrench_recovery_time)


class LimitWatch:
    """Whether the arm can go on following the grasp frame (module doc): how long each joint's
    needed rate and torque have been over its limit (state ``rate_since``, ``torque_since``, s)."""

    def __init__(self, arm: FreeFloatingArm, law: ComputedTorqueLaw, settings: CaptureSettings):
        self.arm, self.law, self.cfg = arm, law, settings
        self.shoulder_id = arm.model.getJointId(settings.shoulder)
        self.arm_names = list(arm.arm_joints)
        self.rate_since = np.full(arm.n, math.nan)
        self.torque_since = np.full(arm.n, math.nan)

    def reset(self) -> None:
        self.rate_since[:], self.torque_since[:] = math.nan, math.nan

    def check(self, t: float, s: ArmState, g: PoseSample, d: PoseSample, qdd: np.ndarray) -> str:
        """Why the arm cannot go on following the grasp frame g on the reference d with the law's
        joint accelerations qdd ('' when it can): the grapple out of reach, or joint rates (needed
        or measured) or torques beyond the URDF limits for longer than limit_window."""
        law, cfg = self.law, self.cfg
        centre = np.array(self.arm.data.oMi[self.shoulder_id].translation)
        distance = float(np.linalg.norm(g.p - centre))
        if distance > cfg.reach:
            return (
                f"the grasp point is {distance:.2f} m from the shoulder; the arm reaches "
                f"{cfg.reach:.2f} m (estimated at t = {t:.3f} s, from {cfg.shoulder})"
            )
        J_plus, _, _ = dls_inverse(s.J_g, law.eps, law.lam)
        momentum_share = s.xdot - s.J_g @ s.qd
        qd_needed = J_plus @ (np.concatenate([d.v, d.w]) - momentum_share)
        qd_needed = np.where(np.abs(s.qd) > np.abs(qd_needed), s.qd, qd_needed)
        tau_needed = s.M_star @ qdd + s.C_star
        for since, needed, limit, what, unit in (
            (self.rate_since, qd_needed, cfg.arm_velocity, "velocity", "rad/s"),
            (self.torque_since, tau_needed, law.effort, "effort", "N m"),
        ):
            over = np.abs(needed) > limit
            since[~over] = math.nan
            since[over & np.isnan(since)] = t
            late = over & (t - since > cfg.limit_window)
            if np.any(late):
                i = int(np.flatnonzero(late)[np.argmax((np.abs(needed) / limit)[late])])
                doing = (
                    f"following the grasp point needs {self.arm_names[i]} at"
                    if what == "velocity"
                    else f"the arm's torques saturate: {self.arm_names[i]} needs"
                )
                return (
                    f"{doing} {abs(needed[i]):.3g} {unit} for {t - since[i]:.3g} s (longer than limit_window = "
                    f"{cfg.limit_window:g} s); its URDF {what} limit is {limit[i]:.3g} {unit}"
                )
        return ""

    def get_state(self) -> dict[str, np.ndarray]:
        return {"rate_since": self.rate_since.copy(), "torque_since": self.torque_since.copy()}

    def set_state(self, read: Callable[[str, int], np.ndarray]) -> None:
        """``read(key, size)``: the state's value, checked."""
        self.rate_since, self.torque_since = read("rate_since", self.arm.n), read("torque_since", self.arm.n)
