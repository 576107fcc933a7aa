r"""Capture of a tumbling target by a free-floating servicer, and the detumbling of the assembly
(issue 23). Plain classes, no bus, no I/O; ``controller.capture``
(:mod:`components.controller.capture_component`) wraps them.

Frames and measurements
-----------------------
W is the dynamics' world frame (docs/design.md §2). The end effector's frame (EE, a link of the
servicer's URDF, z out of the tool) must be brought onto the target's *grasp frame* (the
fixture's frame, z into the target): at capture the two coincide. A pose sensor measures the grasp
frame relative to the EE at time ``t_m`` and delivers it later (latency): ``p`` the grasp origin in
EE axes (m), ``q = q_ee_grasp``. The grasp pose in W at ``t_m`` is

    p_g = p_ee(t_m) + R_ee(t_m) p,    R_g = R_ee(t_m) R(q),

with the EE pose at ``t_m`` (not now) from the Pinocchio model at the measured base and joint state:
the controller keeps the EE poses of the last ``pose_history`` seconds by time (``PoseHistory``),
interpolated between steps (linear in position, geodesic in rotation), extrapolated with the EE
twist when ``t_m`` is newer than the last state.

Estimator (``fit_motion``)
--------------------------
A fading-memory least-squares fit over the last N grasp poses (times t_i, latest t_N,
``tau_i = t_i - t_N``), weights ``exp(tau_i / memory)``:

    position:  p(tau)   = p_0 + v tau + a tau^2 / 2
    attitude:  phi(tau) = phi_0 + w tau + dw tau^2 / 2,   phi_i = log(R_i R_N^T)  (W axes)

(one order less for 2 samples, a constant for 1). For a rotation ``R(tau) = exp(phi(tau)) R_N``
the angular velocity (W) is ``J_l(phi) phi'`` (J_l: left Jacobian of SO(3)); at phi = 0 that is phi'
itself and the second derivative of phi is the angular acceleration (the Jacobian's first-order term
``[phi]x phi' / 2`` vanishes there), so the fit's slope and curvature are the grasp frame's angular
velocity and acceleration at t_N. A rigid motion with constant linear acceleration and a constant
angular velocity is recovered exactly. The estimate at the current time t extrapolates the
polynomials to ``tau = t - t_N``: ``R = exp(phi) R_N``, ``w = J_l(phi) phi'``,
``dw = J_l(phi) phi'' + J_l(phi)' phi'``. Without new measurements the last fit goes on being
extrapolated (``grasp_valid`` = 0 keeps measurements out, not the fit). Deterministic (LAPACK
least squares on the same numbers).

Phases (``phase`` output)
-------------------------
0, approach: until the estimator holds N measurements the arm holds its initial joint
configuration (joint PD with the computed-torque terms below). At the first estimate (time t_0, EE
pose p_0, R_0) a quintic blend ``s(t)`` (components.controller.trajectory.quintic) over
``approach_time`` takes the reference from the EE's pose onto the moving grasp frame:

    p_d = p_0 + s (p_g - p_0),  v_d = s' (p_g - p_0) + s v_g,  a_d = s'' (p_g - p_0) + 2 s' v_g + s a_g
    R_d = exp(r) R_0,  r = s phi,  phi = log(R_g R_0^T)
    w_d = J_l(r) r',  dw_d = J_l(r) r'' + J_l(r)' r',  r' = s' phi + s phi',  r'' = s'' phi + 2 s' phi' + s phi''

with ``J_l(phi) phi' = w_g`` and ``J_l(phi) phi'' = dw_g - J_l(phi)' phi'`` (``left_jacobian_rate``):
the reference's derivatives are exact. The rotation blend assumes the EE and the grasp frame stay
less than 180 deg apart.

1, track: the reference is the estimated grasp frame (pose, velocity, acceleration). Both phases use
:class:`ComputedTorqueLaw` (eqs. 6 and 8, Generalized Jacobian, null-space posture at the initial
configuration); the wheels are passive joints of its model (they get no torque before capture).
The blend is a straight line in W and a geodesic in SO(3): from a start pose on the other side of
a singularity (a stretched elbow, a flipped wrist) the arm cannot follow it, and the limits below
stop the run. ``close`` goes to 1 (and stays) once the estimated errors of the EE relative to the
grasp frame (position, attitude angle, linear velocity, angular velocity) have stayed within
their tolerances for ``tolerance_time``.

2, captured (the ``captured`` input is 1; latched): the arm holds the joint configuration it had at
capture with a joint PD in torque units and the servicer's Coriolis terms,
``tau = K_p (q_hold - q) - K_d qd + C*``: the welded target's inertia, which the model lacks (an
uncooperative target), dwarfs the servicer's M* at the wrist (M* times a gain in 1/s^2 would hold
the target's load with a few N m/rad: 0.4 rad of wrist deflection in a detumble). With the one
step of delay of a sampled loop the hold is stable for ``K_d h`` well below the smallest eigenvalue
of the assembly's M* (about 5 kg m^2 for models/capture with its 300 kg target: K_d = 100 N m s/rad
at h = 10 ms is, 500 is not) and unstable on the bare arm (M* down to 0.004 kg m^2). The reaction
wheels detumble the assembly:
the bus torque ``T = -k omega`` from the IMU rate omega (bus axes); a wheel torque tau_j about its
axis a_j puts ``-tau_j a_j`` on the bus, so ``tau = A^+ k omega`` (A = [a_j], bus axes). A wheel at
its URDF speed limit gets no torque that would spin it faster; the torques are scaled together
(direction kept) to the URDF effort limits, then by a factor that keeps the measured wrist wrench
within ``grasp_force_limit``/``grasp_torque_limit``: whenever the wrench exceeds a limit by the
ratio r > 1 the factor is divided by r; otherwise it recovers linearly to 1 over
``wrench_recovery_time``. Total momentum is never an input.

Beyond the arm (``BeyondArmError``, approach and track only): the estimated grasp point farther
from the shoulder (the first joint of the arm) than the arm's reach (the sum of the joint offsets
from there to the EE); joint rates needed to follow the reference (``J_g^+ (xdot_d - xdot_h)``,
``xdot_h = xdot - J_g qdot`` the momentum's share of the EE twist), or measured, beyond the URDF
velocity limits, or torques (before clipping) beyond the URDF effort limits, either for longer than
``limit_window``. The message says which limit, the figure and the limit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from components.controller.computed_torque import ArmState, ComputedTorqueLaw, FreeFloatingArm, dls_inverse
from components.controller.trajectory import PoseSample, quintic
from components.errors import ComponentError
from components.rotations import exp_so3, log_so3, quat_to_matrix, skew

APPROACH, TRACK, CAPTURED = 0, 1, 2
EMPTY = np.zeros(0)


class BeyondArmError(ComponentError):
    """The grasp point cannot be followed: out of reach, or it needs joint rates or torques beyond
    the URDF limits. The message names the limit, the figure and the limit."""


# --------------------------------------------------------------------------- SO(3)

def left_jacobian(phi) -> np.ndarray:
    """Left Jacobian of SO(3): d/dt exp(phi) = [J_l(phi) phi']x exp(phi)."""
    phi = np.asarray(phi, dtype=float)
    t2 = float(phi @ phi)
    K = skew(phi)
    if t2 < 1e-4:                                 # series: the closed forms cancel at small angles
        a, b = 0.5 - t2 * (1.0 / 24.0 - t2 / 720.0), 1.0 / 6.0 - t2 * (1.0 / 120.0 - t2 / 5040.0)
    else:
        t = math.sqrt(t2)
        a, b = (1.0 - math.cos(t)) / t2, (t - math.sin(t)) / (t2 * t)
    return np.eye(3) + a * K + b * (K @ K)


def left_jacobian_rate(phi, dphi) -> np.ndarray:
    """d/dt J_l(phi(t)) for phi' = dphi: with J_l = I + a(t) K + b(t) K^2, K = [phi]x, t = |phi|,
    its rate is a' t' K + a K' + b' t' K^2 + b (K' K + K K'), K' = [phi']x, t' = phi . phi' / t."""
    phi, dphi = np.asarray(phi, dtype=float), np.asarray(dphi, dtype=float)
    t2 = float(phi @ phi)
    K, dK = skew(phi), skew(dphi)
    dot = float(phi @ dphi)                                  # t t'
    if t2 < 1e-4:                                            # series (the closed forms cancel)
        a, b = 0.5 - t2 * (1.0 / 24.0 - t2 / 720.0), 1.0 / 6.0 - t2 * (1.0 / 120.0 - t2 / 5040.0)
        da_t = -1.0 / 12.0 + t2 * (1.0 / 180.0 - t2 / 6720.0)   # a'(t) / t
        db_t = -1.0 / 60.0 + t2 * (1.0 / 1260.0 - t2 / 90720.0)  # b'(t) / t
    else:
        t = math.sqrt(t2)
        c, sn = math.cos(t), math.sin(t)
        a, b = (1.0 - c) / t2, (t - sn) / (t2 * t)
        da_t = (t * sn - 2.0 * (1.0 - c)) / (t2 * t2)        # a'(t) / t
        db_t = ((1.0 - c) * t - 3.0 * (t - sn)) / (t2 * t2 * t)
    return (da_t * dot) * K + a * dK + (db_t * dot) * (K @ K) + b * (dK @ K + K @ dK)


# --------------------------------------------------------------------------- estimator

@dataclass(frozen=True)
class MotionFit:
    """A fitted rigid motion about the time ``t`` of its latest measurement (module doc).

    | field | unit | meaning |
    |---|---|---|
    | t | s | time of the latest measurement |
    | p, v, a | m, m/s, m/s^2 | position, velocity, acceleration at t (W) |
    | R | - | the latest measured rotation R_W_grasp, the origin of the rotation vectors |
    | phi, dphi, ddphi | rad, rad/s, rad/s^2 | fitted rotation vector relative to R and its rates at t |
    """
    t: float
    p: np.ndarray
    v: np.ndarray
    a: np.ndarray
    R: np.ndarray
    phi: np.ndarray
    dphi: np.ndarray
    ddphi: np.ndarray

    def sample(self, t: float) -> PoseSample:
        """The motion extrapolated to time t (W): p, v, a, R, w, dw."""
        tau = t - self.t
        p = self.p + tau * self.v + (0.5 * tau * tau) * self.a
        phi = self.phi + tau * self.dphi + (0.5 * tau * tau) * self.ddphi
        dphi = self.dphi + tau * self.ddphi
        J = left_jacobian(phi)
        return PoseSample(p, self.v + tau * self.a, self.a.copy(), exp_so3(phi) @ self.R,
                          J @ dphi, J @ self.ddphi + left_jacobian_rate(phi, dphi) @ dphi)

    def to_array(self) -> np.ndarray:
        return np.concatenate([[self.t], self.p, self.v, self.a, self.R.ravel(), self.phi, self.dphi, self.ddphi])

    @classmethod
    def from_array(cls, x) -> "MotionFit":
        x = np.asarray(x, dtype=float)
        if x.size != 28:
            raise ValueError(f"state: a motion fit has 28 values, got {x.size}")
        return cls(float(x[0]), x[1:4].copy(), x[4:7].copy(), x[7:10].copy(), x[10:19].reshape(3, 3).copy(),
                   x[19:22].copy(), x[22:25].copy(), x[25:28].copy())


def fit_motion(times, positions, rotations, memory: float) -> MotionFit:
    """Fading-memory least-squares fit of a rigid motion to poses (module doc).

    ``times`` (k,) s, increasing; ``positions`` (k, 3) m; ``rotations`` (k, 3, 3) R_W_frame;
    ``memory`` s: weight ``exp((t_i - t_k) / memory)`` (inf: equal weights)."""
    times = np.asarray(times, dtype=float)
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    rotations = np.asarray(rotations, dtype=float).reshape(-1, 3, 3)
    k = times.size
    if k == 0 or positions.shape[0] != k or rotations.shape[0] != k:
        raise ValueError(f"fit_motion: expected as many times, positions and rotations (>= 1), got "
                         f"{k}, {positions.shape[0]}, {rotations.shape[0]}")
    t_ref, R_ref = float(times[-1]), rotations[-1].copy()
    tau = times - t_ref
    span = float(-tau[0]) if k > 1 else 1.0
    if not span > 0.0:
        raise ValueError("fit_motion: expected increasing times")
    u = tau / span                                            # in [-1, 0]: a well-conditioned basis
    Y = np.empty((k, 6))
    Y[:, :3] = positions
    Y[:, 3:] = [log_so3(R @ R_ref.T) for R in rotations]
    order = min(2, k - 1)
    A = np.column_stack([np.ones(k), u, 0.5 * u * u][:order + 1])
    sw = np.sqrt(np.exp(tau / memory)) if math.isfinite(memory) else np.ones(k)
    coef = np.linalg.lstsq(A * sw[:, None], Y * sw[:, None], rcond=None)[0]
    c = np.zeros((3, 6))
    c[:order + 1] = coef
    c[1] /= span
    c[2] /= span * span
    return MotionFit(t_ref, c[0, :3], c[1, :3], c[2, :3], R_ref, c[0, 3:], c[1, 3:], c[2, 3:])


class GraspEstimator:
    """The last ``window`` grasp poses (W) and their ``fit_motion`` (refitted at each new one)."""

    def __init__(self, window: int, memory: float):
        if window < 1:
            raise ValueError(f"estimator_window: expected at least 1 measurement, got {window}")
        self.window, self.memory = int(window), float(memory)
        self.t, self.p, self.R = np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3))
        self.fit: MotionFit | None = None

    @property
    def ready(self) -> bool:
        """The window is full: the estimate is used from then on."""
        return self.t.size >= self.window

    def add(self, t: float, p, R) -> None:
        if self.t.size and not t > self.t[-1]:
            raise ValueError(f"grasp measurement at t = {t} s is not newer than the last one ({self.t[-1]} s)")
        keep = slice(max(0, self.t.size + 1 - self.window), None)
        self.t = np.append(self.t, t)[keep]
        self.p = np.vstack([self.p, np.reshape(p, (1, 3))])[keep]
        self.R = np.concatenate([self.R, np.reshape(R, (1, 3, 3))])[keep]
        self.fit = fit_motion(self.t, self.p, self.R, self.memory)

    def get_state(self, prefix: str) -> dict[str, np.ndarray]:
        return {f"{prefix}t": self.t.copy(), f"{prefix}p": self.p.copy(), f"{prefix}R": self.R.copy(),
                f"{prefix}fit": self.fit.to_array() if self.fit is not None else EMPTY.copy()}

    def set_state(self, state: Mapping[str, np.ndarray], prefix: str) -> None:
        t = np.asarray(state[f"{prefix}t"], dtype=float).ravel()
        self.t = t.copy()
        self.p = np.asarray(state[f"{prefix}p"], dtype=float).reshape(t.size, 3).copy()
        self.R = np.asarray(state[f"{prefix}R"], dtype=float).reshape(t.size, 3, 3).copy()
        fit = np.asarray(state[f"{prefix}fit"], dtype=float)
        self.fit = MotionFit.from_array(fit) if fit.size else None


class PoseHistory:
    """End-effector poses and twists (W) by time, the last ``span`` seconds (and the one before,
    to interpolate at the oldest times)."""

    def __init__(self, span: float):
        self.span = float(span)
        self.t, self.p, self.R, self.v, self.w = [], [], [], [], []

    @property
    def full(self) -> bool:
        """It spans ``span`` seconds: a time older than its first is older than ``span``."""
        return bool(self.t) and self.t[-1] - self.t[0] >= self.span

    def record(self, t: float, p, R, v, w) -> None:
        entry = (float(t), np.array(p, dtype=float), np.array(R, dtype=float), np.array(v, dtype=float),
                 np.array(w, dtype=float))
        if self.t and t <= self.t[-1]:
            if t < self.t[-1]:
                raise ValueError(f"end-effector pose at t = {t} s is older than the last one ({self.t[-1]} s)")
            for column, value in zip((self.t, self.p, self.R, self.v, self.w), entry):   # same time: replace
                column[-1] = value
            return
        for column, value in zip((self.t, self.p, self.R, self.v, self.w), entry):
            column.append(value)
        while len(self.t) > 2 and self.t[1] <= t - self.span:
            for column in (self.t, self.p, self.R, self.v, self.w):
                del column[0]

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The pose (p, R) at time t; None when t is older than the oldest pose held."""
        if not self.t or t < self.t[0]:
            return None
        if t >= self.t[-1]:
            dt = t - self.t[-1]
            if dt == 0.0:
                return self.p[-1].copy(), self.R[-1].copy()
            return self.p[-1] + dt * self.v[-1], exp_so3(dt * self.w[-1]) @ self.R[-1]
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        u = (t - self.t[i]) / (self.t[i + 1] - self.t[i])
        p = self.p[i] + u * (self.p[i + 1] - self.p[i])
        R = exp_so3(u * log_so3(self.R[i + 1] @ self.R[i].T)) @ self.R[i]
        return p, R

    def get_state(self, prefix: str) -> dict[str, np.ndarray]:
        n = len(self.t)
        return {f"{prefix}t": np.array(self.t, dtype=float), f"{prefix}p": np.array(self.p).reshape(n, 3),
                f"{prefix}R": np.array(self.R).reshape(n, 3, 3), f"{prefix}v": np.array(self.v).reshape(n, 3),
                f"{prefix}w": np.array(self.w).reshape(n, 3)}

    def set_state(self, state: Mapping[str, np.ndarray], prefix: str) -> None:
        t = np.asarray(state[f"{prefix}t"], dtype=float).ravel()
        n = t.size
        self.t = [float(x) for x in t]
        self.p = [x.copy() for x in np.asarray(state[f"{prefix}p"], dtype=float).reshape(n, 3)]
        self.R = [x.copy() for x in np.asarray(state[f"{prefix}R"], dtype=float).reshape(n, 3, 3)]
        self.v = [x.copy() for x in np.asarray(state[f"{prefix}v"], dtype=float).reshape(n, 3)]
        self.w = [x.copy() for x in np.asarray(state[f"{prefix}w"], dtype=float).reshape(n, 3)]


# --------------------------------------------------------------------------- controller

@dataclass(frozen=True)
class CaptureSettings:
    """Everything the capture controller needs besides its arm model and Cartesian law.

    | field | unit | meaning |
    |---|---|---|
    | approach_time | s | duration of the blend onto the grasp frame |
    | position_tolerance, attitude_tolerance | m, rad | close when the estimated errors stay below... |
    | velocity_tolerance, rate_tolerance | m/s, rad/s | ...these (linear and angular velocity)... |
    | tolerance_time | s | ...for this long |
    | grasp_force_limit, grasp_torque_limit | N, N m | bounds of the measured wrist wrench while detumbling |
    | detumble_gain | N m s/rad | bus torque per bus rate |
    | wrench_recovery_time | s | time for the wheel-torque factor to recover from 0 to 1 |
    | hold_kp, hold_kd | 1/s^2, 1/s (n) | joint hold gains before the first estimate (computed torque) |
    | captured_kp, captured_kd | N m/rad, N m s/rad (n) | joint hold gains after capture (torque units) |
    | estimator_window | - | measurements in the fit |
    | estimator_memory | s | fading-memory time constant of the fit |
    | pose_history | s | end-effector poses kept: the longest measurement latency |
    | limit_window | s | how long joint rates or torques may exceed the URDF limits |
    | shoulder, reach | -, m | centre and radius of the reach sphere |
    | arm_velocity | rad/s (n) | URDF velocity limits of the arm joints |
    | wheel_axes | - (3, m) | wheel spin axes in bus axes (columns) |
    | wheel_effort, wheel_velocity | N m, rad/s (m) | URDF limits of the wheels |
    """
    approach_time: float
    position_tolerance: float
    attitude_tolerance: float
    velocity_tolerance: float
    rate_tolerance: float
    tolerance_time: float
    grasp_force_limit: float
    grasp_torque_limit: float
    detumble_gain: float
    wrench_recovery_time: float
    hold_kp: np.ndarray
    hold_kd: np.ndarray
    captured_kp: np.ndarray
    captured_kd: np.ndarray
    estimator_window: int
    estimator_memory: float
    pose_history: float
    limit_window: float
    shoulder: str
    reach: float
    arm_velocity: np.ndarray
    wheel_axes: np.ndarray
    wheel_effort: np.ndarray
    wheel_velocity: np.ndarray


class CaptureController:
    """The capture controller of one servicer (module doc): arm model, Cartesian law, estimator,
    phases, detumbling. ``start(state)`` takes the arm's initial configuration (the posture and the
    hold before the first estimate); ``step(t, h, inputs)`` returns the outputs for the inputs
    measured at t (h: the control period, s). ``wheels`` are the wheel joints' names (body joints)."""

    def __init__(self, arm: FreeFloatingArm, law: ComputedTorqueLaw, settings: CaptureSettings,
                 wheels: Sequence[str]):
        self.arm, self.law, self.cfg = arm, law, settings
        self.wheel_index = np.array([arm.body_joints.index(j) for j in wheels], dtype=int)
        if self.wheel_index.size:
            self.wheel_map = np.linalg.pinv(np.asarray(settings.wheel_axes, dtype=float).reshape(3, -1))
        else:
            self.wheel_map = np.zeros((0, 3))
        self.shoulder_id = arm.model.getJointId(settings.shoulder)
        self.arm_names = list(arm.arm_joints)
        self.estimator = GraspEstimator(settings.estimator_window, settings.estimator_memory)
        self.history = PoseHistory(settings.pose_history)
        n = arm.n
        self.started = False
        self.q_posture = np.zeros(n)
        self.phase = APPROACH
        self.close = False
        self.anchor: tuple[float, np.ndarray, np.ndarray] | None = None
        self.q_hold = np.zeros(n)
        self.within_since = math.nan
        self.rate_since = np.full(n, math.nan)
        self.torque_since = np.full(n, math.nan)
        self.wheel_scale = 1.0
        self.last_seen = -math.inf            # time of the last measurement looked at
        self.last_distance = 0.0              # |grasp_p| of the last measurement taken

    # ------------------------------------------------------------ lifecycle

    def start(self, state: Mapping[str, np.ndarray]) -> None:
        self.q_posture = np.asarray(state["q"], dtype=float)[self.arm.body_arm].copy()
        self.started = True

    def step(self, t: float, h: float, x: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        arm = self.arm
        arm.set_state(x["position"], x["orientation"], x["twist"], x["q"], x["qd"])
        s = arm.compute(self.law.base_model)
        self.history.record(t, s.p, s.R, s.xdot[:3], s.xdot[3:])
        self._measure(t, x)
        if self.phase != CAPTURED and float(x["captured"]) > 0.5:
            self.phase, self.close, self.q_hold = CAPTURED, True, s.q.copy()
        estimate = self.estimator.fit.sample(t) if self.estimator.ready else None
        tau = np.zeros(arm.n_body)
        reference = estimate
        if self.phase == CAPTURED:
            tau_arm = self._captured_hold(s)
            tau[self.wheel_index] = self._detumble(h, x)
        elif estimate is None:
            tau_arm = self._joint_hold(s, self.q_posture)
        else:
            if self.anchor is None:
                self.anchor = (t, s.p.copy(), s.R.copy())
            reference = self._reference(t, estimate)
            self._check_reach(t, estimate.p)
            out = self.law.control(s, reference, self.q_posture)
            self._check_limits(t, s, reference, out.qdd)
            tau_arm = out.tau
            if self.phase == TRACK:
                self._update_close(t, s, estimate)
        tau[arm.body_arm] = tau_arm
        return self._outputs(s, tau, estimate, reference)

    # ------------------------------------------------------------ estimation

    def _measure(self, t: float, x: Mapping[str, np.ndarray]) -> None:
        """Take a new valid measurement into the estimator (grasp pose in W at its time)."""
        if not float(x["grasp_valid"]) > 0.5:
            return
        t_m = float(x["grasp_t"])
        if not t_m > self.last_seen:
            return
        self.last_seen = t_m
        pose = self.history.at(t_m)
        if pose is None:
            if self.history.full:
                raise ComponentError(
                    f"the grasp measurement of t = {t_m:.6g} s arrives {t - t_m:.6g} s late; the controller keeps "
                    f"end-effector poses for pose_history = {self.cfg.pose_history:g} s: raise pose_history")
            return                                  # taken before the controller's first state
        q = np.asarray(x["grasp_q"], dtype=float)
        if not 0.5 < float(np.linalg.norm(q)) < 2.0:
            raise ComponentError(f"grasp_q: expected a unit quaternion [x, y, z, w], got {q.tolist()}")
        p_ee, R_ee = pose
        p = np.asarray(x["grasp_p"], dtype=float)
        self.estimator.add(t_m, p_ee + R_ee @ p, R_ee @ quat_to_matrix(q))
        self.last_distance = float(np.linalg.norm(p))

    # ------------------------------------------------------------ approach and track

    def _reference(self, t: float, g: PoseSample) -> PoseSample:
        """The blend onto the grasp frame (approach) or the grasp frame itself (track)."""
        t0, p0, R0 = self.anchor
        T = self.cfg.approach_time
        if t >= t0 + T:
            self.phase = TRACK
            return g
        self.phase = APPROACH
        s, ds, dds = quintic(t, t0, T)
        d = g.p - p0
        phi = log_so3(g.R @ R0.T)
        J = left_jacobian(phi)
        dphi = np.linalg.solve(J, g.w)                                        # J_l(phi) phi' = w_g
        ddphi = np.linalg.solve(J, g.dw - left_jacobian_rate(phi, dphi) @ dphi)
        r, dr, ddr = s * phi, ds * phi + s * dphi, dds * phi + 2.0 * ds * dphi + s * ddphi
        J_r = left_jacobian(r)
        return PoseSample(p0 + s * d, ds * d + s * g.v, dds * d + 2.0 * ds * g.v + s * g.a,
                          exp_so3(r) @ R0, J_r @ dr, J_r @ ddr + left_jacobian_rate(r, dr) @ dr)

    def _check_reach(self, t: float, p_grasp: np.ndarray) -> None:
        centre = np.array(self.arm.data.oMi[self.shoulder_id].translation)
        distance = float(np.linalg.norm(p_grasp - centre))
        if distance > self.cfg.reach:
            raise BeyondArmError(f"the grasp point is {distance:.2f} m from the shoulder; the arm reaches "
                                 f"{self.cfg.reach:.2f} m (estimated at t = {t:.3f} s, from {self.cfg.shoulder})")

    def _check_limits(self, t: float, s: ArmState, d: PoseSample, qdd: np.ndarray) -> None:
        """Joint rates needed to follow the reference and torques needed by the law, against the
        URDF limits, each allowed beyond them for ``limit_window``."""
        law, cfg = self.law, self.cfg
        J_plus, _, _ = dls_inverse(s.J_g, law.eps, law.lam)
        momentum_share = s.xdot - s.J_g @ s.qd
        # the rates the reference needs, or the arm's measured rates when higher (the feedback's)
        qd_needed = J_plus @ (np.concatenate([d.v, d.w]) - momentum_share)
        qd_needed = np.where(np.abs(s.qd) > np.abs(qd_needed), s.qd, qd_needed)
        tau_needed = s.M_star @ qdd + s.C_star
        for since, needed, limit, what, unit in (
                (self.rate_since, qd_needed, cfg.arm_velocity, "velocity", "rad/s"),
                (self.torque_since, tau_needed, law.effort, "effort", "N m")):
            over = np.abs(needed) > limit
            since[~over] = math.nan
            since[over & np.isnan(since)] = t
            late = over & (t - since > cfg.limit_window)
            if np.any(late):
                i = int(np.flatnonzero(late)[np.argmax((np.abs(needed) / limit)[late])])
                doing = (f"following the grasp point needs {self.arm_names[i]} at" if what == "velocity" else
                         f"the arm's torques saturate: {self.arm_names[i]} needs")
                raise BeyondArmError(
                    f"{doing} {abs(needed[i]):.3g} {unit} for {t - since[i]:.3g} s (longer than limit_window = "
                    f"{cfg.limit_window:g} s); its URDF {what} limit is {limit[i]:.3g} {unit}")

    def _update_close(self, t: float, s: ArmState, g: PoseSample) -> None:
        if self.close:
            return
        cfg = self.cfg
        within = (float(np.linalg.norm(g.p - s.p)) < cfg.position_tolerance
                  and float(np.linalg.norm(log_so3(g.R @ s.R.T))) < cfg.attitude_tolerance
                  and float(np.linalg.norm(g.v - s.xdot[:3])) < cfg.velocity_tolerance
                  and float(np.linalg.norm(g.w - s.xdot[3:])) < cfg.rate_tolerance)
        if not within:
            self.within_since = math.nan
            return
        if math.isnan(self.within_since):
            self.within_since = t
        if t - self.within_since >= cfg.tolerance_time:
            self.close = True

    # ------------------------------------------------------------ hold and detumble

    def _joint_hold(self, s: ArmState, q_hold: np.ndarray) -> np.ndarray:
        """Computed-torque joint hold of the servicer alone (before the first estimate)."""
        qdd = self.cfg.hold_kp * (q_hold - s.q) - self.cfg.hold_kd * s.qd
        tau = s.M_star @ qdd + s.C_star
        return np.minimum(np.maximum(tau, -self.law.effort), self.law.effort)

    def _captured_hold(self, s: ArmState) -> np.ndarray:
        """Joint PD in torque units plus the servicer's C* (after capture: the target's inertia,
        which the model lacks, dominates M*)."""
        tau = self.cfg.captured_kp * (self.q_hold - s.q) - self.cfg.captured_kd * s.qd + s.C_star
        return np.minimum(np.maximum(tau, -self.law.effort), self.law.effort)

    def _detumble(self, h: float, x: Mapping[str, np.ndarray]) -> np.ndarray:
        cfg = self.cfg
        if not self.wheel_index.size:
            return np.zeros(0)
        tau = self.wheel_map @ (cfg.detumble_gain * np.asarray(x["rate_imu"], dtype=float))
        qd = np.asarray(x["qd"], dtype=float)[self.wheel_index]
        tau[(np.abs(qd) >= cfg.wheel_velocity) & (tau * qd > 0.0)] = 0.0
        ratio = float(np.max(np.abs(tau) / cfg.wheel_effort))
        if ratio > 1.0:
            tau = tau / ratio
        wrench = np.asarray(x["wrench"], dtype=float)
        excess = max(float(np.linalg.norm(wrench[:3])) / cfg.grasp_force_limit,
                     float(np.linalg.norm(wrench[3:])) / cfg.grasp_torque_limit)
        if h > 0.0:                               # once per control period (not at initialize)
            if excess > 1.0:
                self.wheel_scale = self.wheel_scale / excess
            else:
                self.wheel_scale = min(1.0, self.wheel_scale + h / cfg.wrench_recovery_time)
        return self.wheel_scale * tau

    # ------------------------------------------------------------ outputs and state

    def _outputs(self, s: ArmState, tau: np.ndarray, g: PoseSample | None, d: PoseSample | None) -> dict:
        zero = np.zeros(3)
        error = np.zeros(6) if d is None else np.concatenate([d.p - s.p, log_so3(d.R @ s.R.T)])
        return {"tau": tau, "close": np.float64(1.0 if self.close else 0.0), "phase": np.float64(self.phase),
                "grasp_distance": np.float64(self.last_distance if g is None else np.linalg.norm(g.p - s.p)),
                "ee_error": error,
                "grasp_position_est": zero if g is None else g.p,
                "grasp_velocity_est": zero.copy() if g is None else g.v,
                "grasp_rate_est": zero.copy() if g is None else g.w}

    def get_state(self) -> dict[str, np.ndarray]:
        t0, p0, R0 = self.anchor if self.anchor is not None else (math.nan, EMPTY, EMPTY)
        return {"started": np.float64(self.started), "q_posture": self.q_posture.copy(),
                "phase": np.float64(self.phase), "close": np.float64(self.close),
                "anchor_t": np.float64(t0), "anchor_p": np.array(p0, dtype=float),
                "anchor_R": np.array(R0, dtype=float).ravel(), "q_hold": self.q_hold.copy(),
                "within_since": np.float64(self.within_since), "rate_since": self.rate_since.copy(),
                "torque_since": self.torque_since.copy(), "wheel_scale": np.float64(self.wheel_scale),
                "last_seen": np.float64(self.last_seen), "last_distance": np.float64(self.last_distance),
                **self.estimator.get_state("estimator."), **self.history.get_state("history.")}

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        n = self.arm.n

        def vector(key: str, size: int | None) -> np.ndarray:
            if key not in state:
                raise ValueError(f"state: missing {key!r}")
            value = np.asarray(state[key], dtype=float).ravel()
            if size is not None and value.size != size:
                raise ValueError(f"state: {key} expected {size} values, got {value.size}")
            return value.copy()

        self.started = bool(vector("started", 1)[0])
        self.q_posture = vector("q_posture", n)
        self.phase = int(vector("phase", 1)[0])
        self.close = bool(vector("close", 1)[0])
        p0, R0 = vector("anchor_p", None), vector("anchor_R", None)
        self.anchor = None if p0.size == 0 else (float(vector("anchor_t", 1)[0]), p0.reshape(3), R0.reshape(3, 3))
        self.q_hold = vector("q_hold", n)
        self.within_since = float(vector("within_since", 1)[0])
        self.rate_since, self.torque_since = vector("rate_since", n), vector("torque_since", n)
        self.wheel_scale = float(vector("wheel_scale", 1)[0])
        self.last_seen = float(vector("last_seen", 1)[0])
        self.last_distance = float(vector("last_distance", 1)[0])
        self.estimator.set_state(state, "estimator.")
        self.history.set_state(state, "history.")
